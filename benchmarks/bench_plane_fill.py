"""The plane fill again on a finished campaign's own depth maps, setting against setting.

A change to the plane completion (``dense.plane_fill``) is judged by the dense model it
gives, and a whole campaign takes most of an hour per scene. The dense stage keeps every
view's measured depth and normal maps (``final/dense/stereo/*_maps_measured``), so the plane
fill, the fusion and the evaluation can run again on them alone, in minutes: this script
hard-links a finished campaign (``results/{scene}``) into ``--work``/``<variant>`` (nothing of
the campaign is written to), runs :func:`scenebot.dense.planefill.plane_fill` and
:func:`scenebot.dense.stage.fuse` with the variant's ``dense.plane_fill`` settings, then the
evaluate stage (``python -m scenebot evaluate``, depth maps off), and prints completeness,
accuracy and F at 2 and 5 cm per variant, with the ceiling's and the walls' completeness.

    TI_SKIP_VERSION_CHECK=ON .venv/bin/python benchmarks/bench_plane_fill.py \\
        --campaign results/office --variant default --variant nosnap:snap_deg=0

A key ``dense.<name>`` sets the dense stage's own setting instead (``dense.max_views=120``:
the fill and the fusion of fewer reference views, on the maps the full run measured for them,
an upper bound of what a stage computing only those views would give).

Run it once per scene (the office and the flat at least): a plane-fill setting is kept when
it helps across scenes.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")

import numpy as np

from scenebot.config import read_config_file, section_json, validate_config

MEASURED = ("depth_maps_measured", "normal_maps_measured")


def link_scene(src: Path, dst: Path) -> None:
    """``dst``: hard links of the campaign ``src`` without its ``final/`` folder."""
    if dst.exists():
        shutil.rmtree(dst)
    dst.mkdir(parents=True)
    for item in src.iterdir():
        if item.name == "final":
            continue
        if item.is_dir():
            shutil.copytree(item, dst / item.name, copy_function=os.link)
        else:
            os.link(item, dst / item.name)


def link_campaign(src: Path, dst: Path) -> Path:
    """``dst``: hard links of the campaign ``src`` without its final products, and a dense
    workspace holding links of the measured maps (the fill writes its maps anew). Returns
    the new dense folder."""
    link_scene(src, dst)
    dense, src_dense = dst / "final" / "dense", src / "final" / "dense"
    for name in ("sparse", "images"):
        shutil.copytree(src_dense / name, dense / name, copy_function=os.link)
    for name in MEASURED:
        shutil.copytree(src_dense / "stereo" / name, dense / "stereo" / name, copy_function=os.link)
    for cfg in (src_dense / "stereo").glob("*.cfg"):
        shutil.copy(cfg, dense / "stereo" / cfg.name)
    for name in ("depth_maps", "normal_maps"):
        (dense / "stereo" / name).mkdir()
    return dense


def fill_and_fuse(cfg, dense: Path) -> dict:
    """The plane fill and the fusion of the dense stage on ``dense``'s measured maps."""
    import pycolmap

    from scenebot.dense.planefill import plane_fill
    from scenebot.dense.stage import _plan_views, fuse
    from scenebot.dense.workspace import write_configs

    rec = pycolmap.Reconstruction(str(dense / "sparse"))
    plans, _ = _plan_views(cfg, rec)
    # the variant's reference views (dense.max_views ...): fusion reads only those
    write_configs(dense, {p.name: [rec.image(s).name for s in p.sources] for p in plans})
    views = []
    for p in plans:
        img = rec.image(p.image_id)
        pose = img.cam_from_world()
        K = rec.camera(img.camera_id).calibration_matrix()
        R, t = pose.rotation.matrix(), np.asarray(pose.translation)
        views.append((p.name, K, R, t, p.depth_range))
    t0 = time.perf_counter()
    stats = plane_fill(dense, views, cfg.plane_fill, progress=False)
    fused = fuse(cfg, dense)
    return {
        "planes": len(stats["planes"]),
        "planes_dropped": stats["planes_dropped"],
        "fused_points": int(fused.num_points3D()),
        "views": len(plans),
        "seconds": time.perf_counter() - t0,
    }


def evaluate(cfg_doc: dict, scene_dir: Path, round_index: int) -> dict:
    """The evaluate stage's dense figures (depth maps off) of ``scene_dir``'s fused cloud."""
    cfg_doc = json.loads(json.dumps(cfg_doc))
    cfg_doc.setdefault("evaluate", {})["depth_maps"] = False
    params = section_json(validate_config(cfg_doc, "variant"), "scene", "robot", "seed",
                          "world", "sim", "evaluate")  # fmt: skip
    out = scene_dir / "final" / "evaluation.json"
    subprocess.run(
        [sys.executable, "-m", "scenebot", "evaluate", "--params", params, "--scene-dir",
         str(scene_dir), "--round", str(round_index), "--dense",
         str(scene_dir / "final" / "dense" / "fused.ply"), "--observable",
         str(scene_dir / "eval" / "observable_surface.npz"), "--out", str(out)],
        check=True, capture_output=True,
    )  # fmt: skip
    return json.loads(out.read_text())["dense"]


def _value(text: str):
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def variant_parser(description: str, work: str, separator: str) -> argparse.ArgumentParser:
    """The command line of a script that re-runs a stage on a finished campaign, variant
    against variant (``--campaign``, ``--config``, ``--variant``, ``--work``)."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--campaign", type=Path, required=True, help="results/{scene} of a campaign")
    ap.add_argument("--config", type=Path, default=Path("config.yaml"))
    ap.add_argument("--variant", action="append", default=[],
                    help=f"name[:key=value{separator}...]")  # fmt: skip
    ap.add_argument("--work", type=Path, default=Path(work))
    ap.add_argument("--keep-maps", action="store_true",
                    help="keep each variant's depth and normal maps (about 5 MB a view; by "
                    "default removed once the variant is evaluated)")  # fmt: skip
    return ap


def drop_maps(scene_dir: Path) -> None:
    """Remove the depth and normal maps a variant wrote under ``scene_dir``'s ``final/``
    (its stereo folders; the clouds, pictures and summaries stay): a variant of the default
    office writes 1-2.5 GB of them, and a session's variants filled a 29 GB disk."""
    for stereo in (scene_dir / "final").glob("*/stereo"):
        shutil.rmtree(stereo, ignore_errors=True)


def campaign_config(campaign: Path, config: Path) -> tuple[dict, int]:
    """The config the campaign ``campaign`` (results/{scene}) ran with: ``config`` with the
    world and simulator its capture log records, the scene named after its folder; and its
    last round."""
    rounds = json.loads((campaign / "campaign.json").read_text())["rounds"]
    first_log = campaign / "round_000" / "capture" / "log.jsonl"
    session = json.loads(first_log.read_text().splitlines()[0])
    doc = read_config_file(config) | {k: session["config"][k] for k in ("world", "sim")}
    doc["scene"] = campaign.name
    return doc, max(r["round"] for r in rounds)


def variant(spec: str, separator: str) -> tuple[str, list[tuple[str, object]]]:
    """A ``--variant`` as its name and its (key, value) settings (JSON values, else text)."""
    name, _, kv = spec.partition(":")
    items = (item.partition("=") for item in filter(None, kv.split(separator)))
    return name, [(key, _value(val)) for key, _, val in items]


def main() -> int:
    ap = variant_parser(__doc__.split("\n\n")[0], "/tmp/bench_plane_fill", ",")
    args = ap.parse_args()
    doc, round_index = campaign_config(args.campaign, args.config)
    rows = []
    for spec in args.variant or ["default"]:
        name, settings = variant(spec, ",")
        var = json.loads(json.dumps(doc))
        fill = var.setdefault("dense", {}).setdefault("plane_fill", {})
        for key, val in settings:
            if key.startswith("dense."):  # a setting of the dense stage (dense.max_views)
                var["dense"][key.removeprefix("dense.")] = val
            else:
                fill[key] = val
        cfg = validate_config(var, f"variant {name}").dense
        scene_dir = args.work / name / args.campaign.name
        run = fill_and_fuse(cfg, link_campaign(args.campaign, scene_dir))
        dense = evaluate(var, scene_dir, round_index)
        by = {m["material"]: m["completeness"]["2cm"] for m in dense["breakdown"]["by_material"]}
        rows.append((name, dense, by, run))
        if not args.keep_maps:
            drop_maps(scene_dir)
    print("| variant | views | 2 cm: completeness / accuracy / F | 5 cm | ceiling | walls "
          "| planes |")  # fmt: skip
    print("|---|---:|---|---|---:|---:|---:|")
    for name, dense, by, run in rows:
        cells = [
            " / ".join(f"{100 * dense[d][k]:.1f}" for k in ("completeness", "accuracy"))
            + f" / {dense[d]['fscore']:.3f}"
            for d in ("2cm", "5cm")
        ]
        walls = [v for k, v in by.items() if "wall" in k]
        print(f"| {name} | {run['views']} | {cells[0]} | {cells[1]} | "
              f"{100 * by.get('ceiling', 0):.1f}% | {100 * float(np.mean(walls or [0])):.1f}% | "
              f"{run['planes']} |")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
