"""The whole dense stage again on a finished campaign's map, setting against setting.

A change to what PatchMatch computes (``dense.patchmatch``) changes the dense stage's time and
its depth maps; the plane fill after it then makes its own choices (a ceiling found or not, a
wall's shadow kept), which alone move the dense completeness by 5-10 points (issue 23). So each
variant is judged three ways on the same photos and map:

* the **measured depth maps** (PatchMatch after its filter, before the plane fill) against the
  simulator's truth: the share of pixels with a depth and the share of those within 2 % of the
  true depth (``evaluate.depth_maps``), per view and pixel-weighted;
* the **measured cloud**: the fusion of the measured maps alone, its completeness, accuracy and
  F at 2 cm (the plane fill's choices left out);
* the **dense model** the stage writes (plane fill and fusion), as the campaign would have it.

and timed: the stage's own seconds per step (``dense_summary.json``), its process CPU time
over wall time, with the machine's load average before and after. Variants run one after
another in the same session, the first (``default`` unless named) being the reference each
time is divided by.

    TI_SKIP_VERSION_CHECK=ON .venv/bin/python benchmarks/bench_dense_stage.py \\
        --campaign results/office --variant default \\
        --variant sel3:patchmatch.view_selection_levels=3

A variant's keys are ``dense`` settings (dotted: ``patchmatch.iterations=[1,1,3,3]``). Nothing
of the campaign is written to: it is hard-linked into ``--work``/``<variant>`` without its
``final/`` folder.
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")

from bench_plane_fill import (  # benchmarks/ is the script's folder: on sys.path
    campaign_config,
    drop_maps,
    link_scene,
    variant,
    variant_parser,
)

from scenebot.config import section_json, validate_config


def run_stage(doc: dict, scene_dir: Path, last_round: int) -> dict:
    """``python -m scenebot dense`` as the workflow runs it; its summary, wall and CPU time."""
    params = section_json(validate_config(doc, "variant"), "scene", "robot", "seed", "dense")
    out = scene_dir / "final" / "dense"
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "scenebot", "dense", "--params", params, "--sparse",
         str(scene_dir / f"round_{last_round:03d}" / "sfm"), "--images", str(scene_dir),
         "--out", str(out)],
        check=True, capture_output=True,
    )  # fmt: skip
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    summary = json.loads((out / "dense_summary.json").read_text())
    return {"wall": wall, "cpu": cpu, "load": (load0, os.getloadavg()[0]), "summary": summary}


def measured_cloud(doc: dict, scene_dir: Path) -> Path:
    """The fusion of the measured maps alone (``stereo/*_maps_measured``) beside the stage's
    workspace; returns its ``fused.ply``."""
    from scenebot.dense.stage import fuse

    src = scene_dir / "final" / "dense"
    dst = scene_dir / "final" / "dense_measured"
    shutil.rmtree(dst, ignore_errors=True)
    (dst / "stereo").mkdir(parents=True)
    for name in ("sparse", "images"):
        os.symlink(src / name, dst / name)
    for cfg in (src / "stereo").glob("*.cfg"):
        shutil.copy(cfg, dst / "stereo" / cfg.name)
    for kind in ("depth", "normal"):
        final = src / "stereo" / f"{kind}_maps"
        measured = src / "stereo" / f"{kind}_maps_measured"  # flat, by file name
        for path in final.rglob("*.bin"):
            rel = path.relative_to(final)
            link = dst / "stereo" / f"{kind}_maps" / rel
            link.parent.mkdir(parents=True, exist_ok=True)
            os.symlink(measured / rel.name if measured.is_dir() else path, link)
    fuse(validate_config(doc, "variant").dense, dst)
    return dst / "fused.ply"


def evaluate(doc: dict, scene_dir: Path, last_round: int, cloud: Path, depth_maps: bool) -> dict:
    """The evaluate stage's dense figures of ``cloud`` (with the depth maps beside it)."""
    doc = json.loads(json.dumps(doc))
    doc.setdefault("evaluate", {})["depth_maps"] = depth_maps
    doc["evaluate"]["plots"] = False
    params = section_json(validate_config(doc, "variant"), "scene", "robot", "seed", "world",
                          "sim", "evaluate")  # fmt: skip
    out = cloud.parent / "evaluation.json"
    subprocess.run(
        [sys.executable, "-m", "scenebot", "evaluate", "--params", params, "--scene-dir",
         str(scene_dir), "--round", str(last_round), "--dense", str(cloud), "--observable",
         str(scene_dir / "eval" / "observable_surface.npz"), "--out", str(out)],
        check=True, capture_output=True,
    )  # fmt: skip
    return json.loads(out.read_text())["dense"]


def set_key(section: dict, dotted: str, value) -> None:
    *path, last = dotted.split(".")
    for key in path:
        section = section.setdefault(key, {})
    section[last] = value


def main() -> int:
    ap = variant_parser(__doc__.split("\n\n")[0], "/tmp/bench_dense_stage", ";")
    ap.add_argument("--json", type=Path, help="write the rows here too")
    args = ap.parse_args()
    doc, last_round = campaign_config(args.campaign, args.config)
    rows = []
    for spec in args.variant or ["default"]:
        name, settings = variant(spec, ";")
        var = json.loads(json.dumps(doc))
        for key, val in settings:
            set_key(var.setdefault("dense", {}), key, val)
        scene_dir = args.work / name / args.campaign.name
        link_scene(args.campaign, scene_dir)
        print(f"{name}: dense stage ...", file=sys.stderr, flush=True)
        run = run_stage(var, scene_dir, last_round)
        final = evaluate(var, scene_dir, last_round, scene_dir / "final/dense/fused.ply", True)
        measured = evaluate(var, scene_dir, last_round, measured_cloud(var, scene_dir), False)
        rows.append({"name": name, "run": run, "final": final, "measured": measured})
        if not args.keep_maps:
            drop_maps(scene_dir)
        if args.json:
            args.json.write_text(json.dumps(rows, indent=1, default=str))
    print_table(rows)
    return 0


def _cm2(d: dict) -> str:
    c = d["2cm"]
    return f"{100 * c['completeness']:.1f} / {100 * c['accuracy']:.1f} / {c['fscore']:.3f}"


def print_table(rows: list[dict]) -> None:
    ref = rows[0]["run"]
    print("| variant | views | stage s (x ref) | depth / fill / fusion s | CPU/wall | load "
          "| measured maps: coverage, within 2 % (pixels) | measured cloud 2 cm: C / A / F "
          "| dense model 2 cm: C / A / F |")  # fmt: skip
    print("|---|---:|---|---|---:|---|---|---|---|")
    for r in rows:
        run, s = r["run"], r["run"]["summary"]
        dm = r["final"]["depth_maps"]["summary"]["measured"]
        fill = (s.get("plane_fill") or {}).get("seconds", 0.0)
        ratio = run["wall"] / ref["wall"]
        print(
            f"| {r['name']} | {s['num_views']} | {run['wall']:.0f} ({ratio:.2f})"
            f" | {s['depth_seconds']:.0f} / {fill:.0f} / {s['fusion_seconds']:.0f} | "
            f"{run['cpu'] / run['wall']:.2f} | {run['load'][0]:.1f}-{run['load'][1]:.1f} | "
            f"{100 * dm['coverage_pixels']:.1f}%, {100 * dm['within_2pct_pixels']:.1f}% | "
            f"{_cm2(r['measured'])} | {_cm2(r['final'])} |"
        )


if __name__ == "__main__":
    raise SystemExit(main())
