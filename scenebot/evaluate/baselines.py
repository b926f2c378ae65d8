"""Baselines at the adaptive campaign's photo budget: is the paper's heuristic worth it?

Three campaigns of the same simulated scene, each evaluated against the true surface
(dense completeness and accuracy at 1, 2, 5 cm over the observable surface):

* ``adaptive``: the campaign itself (``results/{scene}``), the paper's score choosing goals;
* ``random``: random exploration only (round 0 as in the paper, ``max_rounds: 1``) with as many
  photos as the adaptive campaign took in all;
* ``frontier``: the same rounds as the adaptive campaign, goals from the frontier-style
  chooser (``goals.method: frontier``: nearest boundary of seen and unseen free space).

Each baseline is a full campaign of this workflow in ``results/{scene}/baselines/<name>/``
(run by a nested ``snakemake`` with the campaign's config plus the overrides above), so every
intermediate stays there to open. ``baselines.json`` and ``baselines.png`` (completeness per
photo count) sum them up.
"""

from __future__ import annotations

import copy
import json
import logging
import subprocess
import sys
import time
from pathlib import Path

import yaml

from scenebot.evaluate.metrics import EvaluationError

LOG = logging.getLogger(__name__)

METHODS = ("random", "frontier")


def baseline_config(campaign: dict, method: str, photos_total: int) -> dict:
    """The campaign's config (plain dict) changed into a baseline's.

    Args:
        campaign: the adaptive campaign's config as a dict (``config.yaml`` merged).
        method: ``random`` or ``frontier``.
        photos_total: photos the adaptive campaign took in all.
    """
    cfg = copy.deepcopy(campaign)
    if method == "random":
        cfg["max_rounds"] = 1
        cfg.setdefault("exploration", {})["photos"] = int(photos_total)
    elif method == "frontier":
        cfg.setdefault("goals", {})["method"] = "frontier"
    else:
        raise ValueError(f"unknown baseline {method!r}; known: {', '.join(METHODS)}")
    # the baselines' own score-validity study would repeat the adaptive one
    cfg.setdefault("evaluate", {})["validity_candidates"] = 0
    return cfg


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
        "dense": {k: v for k, v in dense.items() if k.endswith("cm")},
        "dense_points": dense.get("points"),
        "goals": (ev.get("capture") or {}).get("goals"),
        "stopped_because": camp.get("stopped_because"),
    }


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
    for method in methods:
        work = (scene_dir / "baselines" / method).resolve()
        work.mkdir(parents=True, exist_ok=True)
        cfg = baseline_config(campaign_cfg, method, adaptive["photos"])
        (work / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
        log = work / "snakemake.log"
        cmd = [sys.executable, "-m", "snakemake", "-s", str(snakefile), "-d", str(work),
               "--configfile", str(work / "config.yaml"), "--cores", str(cores)]  # fmt: skip
        LOG.info("baseline %s: %s (log %s)", method, " ".join(cmd), log)
        with open(log, "w") as fh:
            res = subprocess.run(cmd, stdout=fh, stderr=subprocess.STDOUT, cwd=work)
        if res.returncode != 0:
            raise EvaluationError(f"baseline {method} failed (exit {res.returncode}); see {log}")
        scene = cfg.get("scene", "office")
        out[method] = _summary(work / "results" / scene)
    out["seconds"] = time.perf_counter() - t0
    out_json = Path(out_json)
    out_json.parent.mkdir(parents=True, exist_ok=True)
    out_json.write_text(json.dumps(out, indent=1))
    plot_baselines(out, out_json.with_suffix(".png"))
    return out


def plot_baselines(summary: dict, png: Path) -> Path:
    """Completeness (and accuracy) at 2 cm against photo count, one marker per campaign."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2), dpi=100)
    colors = {"adaptive": "tab:red", "random": "tab:blue", "frontier": "tab:green"}
    for name, s in summary.items():
        if not isinstance(s, dict) or "dense" not in s:
            continue
        for ax, key in zip(axes, ("completeness", "accuracy"), strict=True):
            for th, marker in (("1cm", "v"), ("2cm", "o"), ("5cm", "^")):
                if th not in s["dense"]:
                    continue
                ax.plot(s["photos"], 100 * s["dense"][th][key], marker, color=colors.get(name),
                        ms=9 if th == "2cm" else 6,
                        label=f"{name} ({th})" if th == "2cm" else None)  # fmt: skip
    for ax, key in zip(axes, ("completeness", "accuracy"), strict=True):
        ax.set_xlabel("photos taken in all")
        ax.set_ylabel(f"dense {key} (%)")
        ax.set_title(f"{key} at 1 / 2 / 5 cm (v o ^)", fontsize=10)
        ax.grid(alpha=0.3)
    axes[0].legend(loc="best", fontsize=8)
    fig.suptitle("adaptive (the paper's score) vs baselines at the same photo budget")
    fig.tight_layout()
    fig.savefig(png)
    plt.close(fig)
    return png
