"""Baselines at the adaptive campaign's photo budget: is the paper's heuristic worth it?

Three campaigns of the same simulated scene, each evaluated against the true surface
(dense completeness and accuracy at 1, 2, 5 cm over the observable surface):

* ``adaptive``: the campaign itself (``results/{scene}``), the paper's score choosing goals;
* ``random``: random exploration only (round 0 as in the paper, ``max_rounds: 1``) with as many
  photos as the adaptive campaign took in all;
* ``frontier``: the same rounds as the adaptive campaign, goals from the frontier-style
  chooser (``goals.method: frontier``: nearest boundary of seen and unseen free space).

Each baseline is a campaign of this workflow in ``results/{scene}/baselines/<name>/`` (run by
a nested ``snakemake`` with the campaign's config plus the overrides above, up to its dense
model's evaluation: no tour or score validity), so every intermediate stays there to open.
``baselines.json`` and ``baselines.png`` sum them up: per campaign, the coverage curve (share
of the observable area seen by >= 1 and >= 2 of the first n photos in capture order, n = 5,
10, ..., N: ``coverage_by_photos`` of its ``final/evaluation.json``,
:func:`scenebot.evaluate.breakdown.coverage_by_photo_count`) with the dense completeness at N,
and the dense accuracy.

:func:`refresh_baselines` (``python -m scenebot baselines --replot-only``) summarizes the
campaigns already run again and redraws the plot without running anything; a campaign
evaluated before the coverage curve existed gets it computed here (one 160x120 visibility
render per photo against the true scene).
"""

from __future__ import annotations

import copy
import json
import logging
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import yaml

from scenebot.evaluate.breakdown import COVERAGE_STEP
from scenebot.evaluate.config import EvaluateConfig
from scenebot.evaluate.metrics import EvaluationError

LOG = logging.getLogger(__name__)

METHODS = ("random", "frontier")


def baseline_config(
    campaign: dict, method: str, photos_total: int, rounds: int | None = None
) -> dict:
    """The campaign's config (plain dict) changed into a baseline's.

    Args:
        campaign: the adaptive campaign's config as a dict (``config.yaml`` merged).
        method: ``random`` or ``frontier``.
        photos_total: photos the adaptive campaign took in all.
        rounds: rounds the adaptive campaign ran (the frontier baseline runs as many, so
            both take the same photos when the adaptive one stopped before ``max_rounds``);
            None: the campaign's ``max_rounds``.

    The baseline shares the campaign's cache (``evaluate.cache_dir``, the observable surface
    of the same scene): a folder the campaign names is made absolute here (the baseline runs
    in its own folder); unset, the baseline's run inherits the environment
    (``SCENEBOT_CACHE``, ``XDG_CACHE_HOME``: :func:`_nested_env`).
    """
    cfg = copy.deepcopy(campaign)
    if method == "random":
        cfg["max_rounds"] = 1
        cfg.setdefault("exploration", {})["photos"] = int(photos_total)
    elif method == "frontier":
        cfg.setdefault("goals", {})["method"] = "frontier"
        if rounds is not None:
            cfg["max_rounds"] = int(rounds)
    else:
        raise ValueError(f"unknown baseline {method!r}; known: {', '.join(METHODS)}")
    # the baselines' own score-validity study would repeat the adaptive one
    ev = cfg.setdefault("evaluate", {})
    ev["validity_candidates"] = 0
    if ev.get("cache_dir"):  # relative or ~: the same folder from the baseline's own folder
        ev["cache_dir"] = str(EvaluateConfig(cache_dir=ev["cache_dir"]).cache_folder())
    return cfg


def _nested_env(snakefile: Path) -> dict[str, str]:
    """The environment of a nested baseline run: ``python -m scenebot`` runs in the
    baseline's own folder, so without the workflow's folder first on ``PYTHONPATH`` it would
    import whichever ``scenebot`` is installed (an editable install of another checkout),
    not the package beside the Snakefile the adaptive campaign ran."""
    import os

    env = dict(os.environ)
    root = str(Path(snakefile).resolve().parent)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH", "")) if p)
    return env


def _summary(scene_dir: Path) -> dict:
    ev_path = scene_dir / "final" / "evaluation.json"
    camp_path = scene_dir / "campaign.json"
    if not ev_path.is_file() or not camp_path.is_file():
        raise EvaluationError(f"{scene_dir}: no final/evaluation.json or campaign.json")
    ev = json.loads(ev_path.read_text())
    camp = json.loads(camp_path.read_text())
    dense = ev.get("dense") or {}
    return {
        "dir": str(scene_dir),
        "photos": camp.get("photos_total"),
        "rounds": len(camp.get("rounds", [])),
        "registered": camp["rounds"][-1].get("registered") if camp.get("rounds") else None,
        "photos_per_round": (ev.get("capture") or {}).get("photos_per_round"),
        "dense": {k: v for k, v in dense.items() if k.endswith("cm")},
        "dense_points": dense.get("points"),
        "goals": (ev.get("capture") or {}).get("goals"),
        "stopped_because": camp.get("stopped_because"),
        "coverage_by_photos": ev.get("coverage_by_photos"),
    }


def _truth(campaign: dict) -> tuple[object, float]:
    """(true scene, photos' horizontal field of view) of a campaign config (plain dict)."""
    from scenebot.config import validate_config
    from scenebot.scene.loader import load_world_scene

    cfg = validate_config({k: v for k, v in campaign.items() if k != "evaluate"}, "campaign")
    return load_world_scene(cfg.world), cfg.sim.camera.hfov_deg


def campaign_coverage(
    scene_dir: Path, scene, hfov_deg: float, step: int = COVERAGE_STEP
) -> dict[str, list]:
    """A campaign's coverage curve from its files, as the evaluate stage computes it.

    Args:
        scene_dir: the campaign's ``results/{scene}`` (``campaign.json``, the rounds'
            ``capture/log.jsonl`` with true poses, ``eval/observable_surface.npz``).
        scene: the true scene.
        hfov_deg: the photos' horizontal field of view (deg).
        step: photos between two points of the curve.

    Returns:
        :func:`scenebot.evaluate.breakdown.coverage_by_photo_count`'s curve.
    """
    from scenebot.evaluate.breakdown import coverage_by_photo_count, photo_visibility
    from scenebot.evaluate.metrics import true_photo_poses
    from scenebot.evaluate.observable import ObservableSurface

    scene_dir = Path(scene_dir)
    obs = scene_dir / "eval" / "observable_surface.npz"
    camp = scene_dir / "campaign.json"
    if not obs.is_file() or not camp.is_file():
        raise EvaluationError(f"{scene_dir}: no eval/observable_surface.npz or campaign.json")
    rounds = [r["round"] for r in json.loads(camp.read_text()).get("rounds", [])]
    caps = [scene_dir / f"round_{r:03d}" / "capture" for r in sorted(rounds)]
    surf = ObservableSurface.load(obs)
    vis = photo_visibility(surf.observable_points, true_photo_poses(caps), scene, hfov_deg)
    return coverage_by_photo_count(vis, surf.observable_weights, step)


def _fill_coverage(summary: dict, configs: dict[str, dict]) -> float:
    """Compute the coverage curves the campaigns' evaluations lack (evaluated before the
    curve existed); ``configs``: campaign name -> its config. Returns the seconds spent."""
    t0 = time.perf_counter()
    truths: dict[str, tuple] = {}
    for name, s in summary.items():
        if not isinstance(s, dict) or "dir" not in s or s.get("coverage_by_photos"):
            continue
        cfg = configs[name]
        key = json.dumps([cfg.get("world"), cfg.get("sim")], sort_keys=True)
        if key not in truths:
            truths[key] = _truth(cfg)
        LOG.info("coverage curve of %s (%s)", name, s["dir"])
        s["coverage_by_photos"] = campaign_coverage(Path(s["dir"]), *truths[key])
    return time.perf_counter() - t0


def run_baselines(
    campaign_cfg: dict,
    scene_dir: Path,
    out_json: Path,
    methods: tuple[str, ...] = METHODS,
    cores: int = 2,
    snakefile: Path | None = None,
) -> dict:
    """Run the baseline campaigns (those not yet done) and compare them with the adaptive one.

    Args:
        campaign_cfg: the adaptive campaign's config (the workflow's ``config``: config.yaml
            with the command line's ``--config`` merged).
        scene_dir: the adaptive campaign's ``results/{scene}``.
        out_json: ``baselines.json`` (``baselines.png`` beside it).
        methods: which baselines.
        cores: cores of the nested snakemake runs.
        snakefile: the workflow (default: the one next to this package).

    Raises:
        EvaluationError: the adaptive campaign has no evaluation, or a baseline run failed
            (its log is named).
    """
    t0 = time.perf_counter()
    scene_dir = Path(scene_dir)
    adaptive = _summary(scene_dir)
    snakefile = snakefile or Path(__file__).resolve().parents[2] / "Snakefile"
    out = {"adaptive": adaptive}
    configs = {"adaptive": campaign_cfg}
    for method in methods:
        work = (scene_dir / "baselines" / method).resolve()
        work.mkdir(parents=True, exist_ok=True)
        cfg = baseline_config(campaign_cfg, method, adaptive["photos"], adaptive["rounds"])
        (work / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
        log = work / "snakemake.log"
        scene = cfg.get("scene", "office")
        # what the comparison reads: the campaign and its evaluation (dense model included),
        # not the tour, the score validity or the timing picture of a baseline
        targets = [f"results/{scene}/campaign.json", f"results/{scene}/final/evaluation.json"]
        cmd = [sys.executable, "-m", "snakemake", "-s", str(snakefile), "-d", str(work),
               "--configfile", str(work / "config.yaml"), "--cores", str(cores),
               *targets]  # fmt: skip
        LOG.info("baseline %s: %s (log %s)", method, " ".join(cmd), log)
        with open(log, "w") as fh:
            res = subprocess.run(cmd, stdout=fh, stderr=subprocess.STDOUT, cwd=work,
                                 env=_nested_env(snakefile))  # fmt: skip
        if res.returncode != 0:
            raise EvaluationError(f"baseline {method} failed (exit {res.returncode}); see {log}")
        out[method] = _summary(work / "results" / scene)
        configs[method] = cfg
    _fill_coverage(out, configs)
    out["seconds"] = time.perf_counter() - t0
    out_json = Path(out_json)
    out_json.parent.mkdir(parents=True, exist_ok=True)
    out_json.write_text(json.dumps(out, indent=1))
    plot_baselines(out, out_json.with_suffix(".png"))
    return out


def refresh_baselines(
    campaign_cfg: dict,
    scene_dir: Path,
    out_json: Path,
    methods: tuple[str, ...] = METHODS,
) -> dict:
    """Summarize the baseline campaigns already run again and redraw ``baselines.png``,
    running none (coverage curves the evaluations lack are computed).

    Args:
        campaign_cfg: the adaptive campaign's config (plain dict).
        scene_dir: the adaptive campaign's ``results/{scene}``.
        out_json: ``baselines.json`` (rewritten; its ``seconds``, the runs' time, is kept).
        methods: the baselines to include; those with no campaign in
            ``results/{scene}/baselines/<name>/`` are left out with a warning.
    """
    t0 = time.perf_counter()
    scene_dir = Path(scene_dir)
    out_json = Path(out_json)
    old = json.loads(out_json.read_text()) if out_json.is_file() else {}
    out = {"adaptive": _summary(scene_dir)}
    configs = {"adaptive": campaign_cfg}
    for method in methods:
        work = (scene_dir / "baselines" / method).resolve()
        cfg_path = work / "config.yaml"
        if not cfg_path.is_file():
            LOG.warning("baseline %s: no campaign in %s; left out", method, work)
            continue
        cfg = yaml.safe_load(cfg_path.read_text())
        out[method] = _summary(work / "results" / cfg.get("scene", "office"))
        configs[method] = cfg
    out["coverage_seconds"] = _fill_coverage(out, configs)
    if "seconds" in old:
        out["seconds"] = old["seconds"]
    out["refresh_seconds"] = time.perf_counter() - t0
    out_json.parent.mkdir(parents=True, exist_ok=True)
    out_json.write_text(json.dumps(out, indent=1))
    plot_baselines(out, out_json.with_suffix(".png"))
    return out


def _shared_prefix(curves: list[dict]) -> int:
    """The largest photo count up to which every curve has the same points (0: none)."""
    if len(curves) < 2 or not all(c.get("photos") for c in curves):
        return 0
    shared = 0
    rows = [zip(c["photos"], c["seen_1"], c["seen_2"], strict=True) for c in curves]
    for pts in zip(*rows, strict=False):  # up to the shortest curve
        if any(p != pts[0] for p in pts[1:]):
            break
        shared = pts[0][0]
    return shared


def plot_baselines(summary: dict, png: Path) -> Path:
    """Left: coverage of the observable surface against photos taken (seen by >= 2 of the
    first n photos, solid; >= 1, dashed) per campaign, with its dense completeness at 2 cm
    at N (big marker). Right: dense accuracy at 1 / 2 / 5 cm per campaign."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    fig, (ax_c, ax_a) = plt.subplots(1, 2, figsize=(12, 4.8), dpi=100,
                                     gridspec_kw={"width_ratios": [1.7, 1]})  # fmt: skip
    colors = {"adaptive": "tab:red", "random": "tab:blue", "frontier": "tab:green"}
    runs = {k: s for k, s in summary.items() if isinstance(s, dict) and "dense" in s}
    ppr = (runs.get("adaptive") or {}).get("photos_per_round") or []
    for k, start in enumerate(np.cumsum(ppr)[:-1], start=1):
        ax_c.axvline(start, color="0.6", lw=0.8, ls=":")
        ax_c.text(start, 0.98, f" adaptive\n round {k}", color="0.4", fontsize=7, va="top",
                  transform=ax_c.get_xaxis_transform())  # fmt: skip
    handles = []
    for x, (name, s) in enumerate(runs.items()):
        color = colors.get(name)
        cov = s.get("coverage_by_photos") or {}
        if cov.get("photos"):
            ax_c.plot(cov["photos"], 100 * np.asarray(cov["seen_2"]), "-", color=color, lw=2)
            ax_c.plot(cov["photos"], 100 * np.asarray(cov["seen_1"]), "--", color=color, lw=1.2)
        comp = (s["dense"].get("2cm") or {}).get("completeness")
        label = f"{name}: {s['photos']} photos"
        if comp is not None:
            # smaller for each later campaign: equal figures at equal photo counts stay visible
            ax_c.plot(s["photos"], 100 * comp, "o", color=color, ms=13 - 3 * x, mec="k")
            label += f", {100 * comp:.1f}% complete at 2 cm"
        handles.append(Line2D([], [], color=color, lw=2, label=label))
        for th, marker in (("1cm", "v"), ("2cm", "o"), ("5cm", "^")):
            if th in s["dense"]:
                ax_a.plot(x, 100 * s["dense"][th]["accuracy"], marker, color=color,
                          ms=10 if th == "2cm" else 7)  # fmt: skip
    shared = _shared_prefix([s.get("coverage_by_photos") or {} for s in runs.values()])
    if shared:
        ax_c.text(shared / 2, 3, f"all {len(runs)} curves coincide up to {shared} photos",
                  ha="center", fontsize=8, color="0.3")  # fmt: skip
    handles += [
        Line2D([], [], color="k", lw=2, label="seen by >= 2 of the first n photos"),
        Line2D([], [], color="k", lw=1.2, ls="--", label="seen by >= 1"),
        Line2D([], [], color="0.6", marker="o", ms=9, mec="k", ls="",
               label="dense complete at 2 cm (at N)"),
    ]  # fmt: skip
    ax_c.legend(handles=handles, loc="lower right", fontsize=8)
    ax_c.set_xlabel("photos taken (first n, in capture order)")
    ax_c.set_ylabel("% of the observable surface (area)")
    ax_c.set_ylim(0, 100)
    ax_c.set_xlim(left=0)
    ax_c.set_title("coverage of the observable surface vs photos taken; dense completeness",
                   fontsize=10)  # fmt: skip
    ax_c.grid(alpha=0.3)
    ax_a.set_xticks(range(len(runs)), [f"{n}\n({s['photos']} photos)" for n, s in runs.items()])
    ax_a.set_xlim(-0.6, len(runs) - 0.4)
    ax_a.set_ylabel("dense accuracy (% of the cloud)")
    ax_a.set_title("dense accuracy at the end", fontsize=10)
    ax_a.legend(handles=[Line2D([], [], color="0.4", marker=m, ls="", label=f"within {th}")
                         for m, th in (("v", "1 cm"), ("o", "2 cm"), ("^", "5 cm"))],
                loc="lower right", fontsize=8)  # fmt: skip
    ax_a.grid(alpha=0.3, axis="y")
    fig.suptitle("adaptive (the paper's score) vs baselines at the same photo budget")
    fig.tight_layout()
    fig.savefig(png)
    plt.close(fig)
    return png
