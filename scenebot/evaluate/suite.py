"""The scene suite: one set of settings measured on many scenes (issue 23).

* :func:`scene_configs` (read by ``rules/suite.smk`` when the workflow starts: standard
  library only at the top): the config of each suite scene's campaign, the workflow's
  config with the scene's world, in ``results/suite/<name>/``.
* :func:`run` (rule ``suite_report``, ``python -m scenebot suite-report``): per scene the
  figures of its final evaluation (``final/evaluation.json``) and the margins over its
  baselines (``baselines/baselines.json``), the median and the worst scene, written as
  ``suite.json``, ``suite.md`` and ``suite.png``. It reads only those files: nothing is
  computed again.
"""

from __future__ import annotations

import copy
import json
import statistics
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

RESULTS = "results/suite"
"""Where the suite's campaigns (``<name>/``: ``scene: suite/<name>``) and its summary
(``suite.*``) go."""
SIMULATED = ("sim", "nxt-emulated")
METHODS = ("random", "frontier")
"""The baselines each adaptive campaign can be compared with (``baselines.json``; those run
are ``suite.baselines``, the margins over the others are empty)."""

# (key, what, unit): the figures of a scene's row, in the order suite.md shows them; the
# median and the worst scene are taken over each of them (the worst is the lowest,
# dense_2cm_completeness decides which scene is "the worst scene")
COLUMNS = (
    ("photos", "photos taken", "count"),
    ("registered", "photos registered", "count"),
    ("registered_fraction", "registered / taken", "share"),
    ("goals_reachable", "truly reachable goals", "count"),
    ("goals_reached", "reachable goals reached within 10 cm", "count"),
    ("goals_reached_fraction", "reached / reachable", "share"),
    ("completeness_2cm", "dense completeness at 2 cm", "share"),
    ("accuracy_2cm", "dense accuracy at 2 cm", "share"),
    ("fscore_2cm", "F at 2 cm", "share"),
    ("completeness_5cm", "dense completeness at 5 cm", "share"),
    ("accuracy_5cm", "dense accuracy at 5 cm", "share"),
    ("fscore_5cm", "F at 5 cm", "share"),
    ("seen_2", "observable area seen by >= 2 photos", "share"),
    ("margin_random", "completeness at 2 cm over random exploration", "points"),
    ("margin_frontier", "completeness at 2 cm over the frontier chooser", "points"),
)
WORST_BY = "completeness_2cm"


class SuiteError(ValueError):
    """A suite that cannot be summed up (a scene's file missing or without its figures)."""


# ---------------------------------------------------------------------------- configs
def _merged(base: dict, extra: dict) -> dict:
    """``base`` with ``extra`` merged in, mapping by mapping (a list or value replaces)."""
    out = copy.deepcopy(base)
    for k, v in extra.items():
        out[k] = _merged(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def scene_configs(config: dict[str, Any], suite) -> dict[str, dict[str, Any]]:
    """The config of each suite scene's campaign (name -> plain dict, as config.yaml).

    The workflow's config (``config.yaml`` with ``--configfile`` and ``--config``: the one
    set of settings the suite measures) with ``scene: suite/<name>`` (results in
    ``results/suite/<name>/``), the scene's world in place of the campaign's (its start and
    floor height too) and the scene's ``overrides``. A scene is simulated (the suite
    evaluates against the truth): ``robot: sim`` unless the workflow's is ``nxt-emulated``,
    without a person's photos or their reference cameras. Its own ``suite`` has no scenes
    (a scene's campaign is one campaign) and the suite's ``baselines`` (the methods its
    ``baselines`` rule runs).

    Args:
        config: the workflow's config (Snakemake's ``config``).
        suite: the :class:`scenebot.evaluate.config.SuiteConfig`.
    """
    base = copy.deepcopy(config)
    base.pop("photos", None)
    if base.get("robot") not in SIMULATED:
        base["robot"] = "sim"
    ev = base.get("evaluate")
    if isinstance(ev, dict):
        for key in ("reference_cameras", "reference_world", "reference_bbox"):
            ev.pop(key, None)
    methods = list(suite.baselines)
    out = {}
    for s in suite.scenes:
        cfg = dict(base, scene=f"suite/{s.name}", suite={"scenes": [], "baselines": methods})
        cfg["world"] = {
            "builtin": s.builtin,
            "file": None if s.file is None else str(s.file),
            "seed": s.seed,
        }
        out[s.name] = _merged(cfg, s.overrides)
    return out


def scene_files(names, path: str) -> list[str]:
    """A file of each suite scene's campaign (``results/suite/<name>/<path>``), in order."""
    return [f"{RESULTS}/{name}/{path}" for name in names]


# ---------------------------------------------------------------------------- the stage
@dataclass
class SuiteInputs:
    """Per scene, in the order of ``names``: its final evaluation and its baselines."""

    evaluations: list[Path] = field(default_factory=list)
    baselines: list[Path] = field(default_factory=list)


@dataclass
class SuiteOutputs:
    suite_json: Path
    suite_md: Path
    suite_png: Path


def _read(path: Path, name: str, what: str) -> dict:
    path = Path(path)
    if not path.is_file():
        raise SuiteError(f"suite scene {name!r}: no {what} ({path})")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise SuiteError(f"suite scene {name!r}: {path} is not JSON: {exc}") from None


def _share(num, den) -> float | None:
    return None if num is None or not den else num / den


def scene_row(name: str, evaluation: dict, baselines: dict) -> dict[str, Any]:
    """A scene's figures (:data:`COLUMNS`) from its final evaluation and its baselines.

    Args:
        name: the scene.
        evaluation: its ``final/evaluation.json``.
        baselines: its ``baselines/baselines.json`` (``random`` and ``frontier``: each a
            campaign's summary with ``dense`` per threshold).

    Raises:
        SuiteError: the evaluation has no dense figures (a campaign without its dense
            model, or not simulated).
    """
    dense = evaluation.get("dense") or {}
    if "2cm" not in dense or "5cm" not in dense:
        raise SuiteError(
            f"suite scene {name!r}: its final evaluation has no dense figures at 2 and 5 cm"
        )
    cap = evaluation.get("capture") or {}
    goals = evaluation.get("goals_truth") or {}
    breakdown = dense.get("breakdown") or {}
    seen_2 = breakdown.get("photographed_share")
    if seen_2 is None:  # the coverage curve's last point is the same share
        curve = (evaluation.get("coverage_by_photos") or {}).get("seen_2") or []
        seen_2 = curve[-1] if curve else None
    photos = cap.get("photos_total")
    registered = (evaluation.get("sfm") or {}).get("registered")
    row = {
        "scene": name,
        "photos": photos,
        "registered": registered,
        "registered_fraction": _share(registered, photos),
        "goals_reachable": goals.get("reachable"),
        "goals_reached": goals.get("reached_within"),
        "goals_reached_fraction": goals.get("reached_within_fraction_of_reachable"),
        "seen_2": seen_2,
    }
    for th in ("2cm", "5cm"):
        row[f"completeness_{th}"] = dense[th]["completeness"]
        row[f"accuracy_{th}"] = dense[th]["accuracy"]
        row[f"fscore_{th}"] = dense[th]["fscore"]
    for method in METHODS:
        other = ((baselines.get(method) or {}).get("dense") or {}).get("2cm") or {}
        comp = other.get("completeness")
        row[f"{method}_completeness_2cm"] = comp
        row[f"{method}_photos"] = (baselines.get(method) or {}).get("photos")
        row[f"margin_{method}"] = None if comp is None else 100.0 * (row["completeness_2cm"] - comp)
    return row


def summary_rows(rows: list[dict]) -> dict[str, dict]:
    """The median over the scenes of each figure, and the worst scene (the lowest dense
    completeness at 2 cm) with its figures; and, per figure, the lowest value and its scene."""
    median, lowest = {}, {}
    for key, _, _ in COLUMNS:
        values = [(r[key], r["scene"]) for r in rows if r.get(key) is not None]
        median[key] = statistics.median(v for v, _ in values) if values else None
        lowest[key] = min(values) if values else None
    worst = min(rows, key=lambda r: r[WORST_BY]) if rows else None
    return {
        "median": median,
        "worst": dict(worst) if worst else None,
        "lowest": {k: {"value": v[0], "scene": v[1]} for k, v in lowest.items() if v},
    }


def run(names: list[str], inputs: SuiteInputs, outputs: SuiteOutputs) -> dict:
    """Sum up the suite: ``suite.json`` (scenes, median, worst), ``suite.md``, ``suite.png``.

    Raises:
        SuiteError: no scenes, names and files that do not pair up, or a scene whose file is
            missing or lacks its figures (the scene is named).
    """
    if not names:
        raise SuiteError("the suite has no scenes (suite.scenes in the config)")
    if not (len(names) == len(inputs.evaluations) == len(inputs.baselines)):
        raise SuiteError(
            f"{len(names)} scene names, {len(inputs.evaluations)} evaluations and "
            f"{len(inputs.baselines)} baselines: give one of each per scene, in order"
        )
    rows = []
    for name, ev_path, base_path in zip(names, inputs.evaluations, inputs.baselines, strict=True):
        ev = _read(ev_path, name, "final evaluation")
        base = _read(base_path, name, "baselines")
        row = scene_row(name, ev, base)
        row["evaluation"], row["baselines"] = str(ev_path), str(base_path)
        rows.append(row)
    doc = {"scenes": rows, **summary_rows(rows), "columns": [list(c) for c in COLUMNS]}
    for path in (outputs.suite_json, outputs.suite_md, outputs.suite_png):
        Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(outputs.suite_json).write_text(json.dumps(doc, indent=1), encoding="utf-8")
    Path(outputs.suite_md).write_text(markdown(doc), encoding="utf-8")
    plot_suite(doc, Path(outputs.suite_png))
    return {"scenes": len(rows), "median": doc["median"], "worst": doc["worst"]["scene"]}


# ---------------------------------------------------------------------------- pictures
def _fmt(value, unit: str) -> str:
    if value is None:
        return "-"
    if unit == "share":
        return f"{100 * value:.1f}%"
    if unit == "points":
        return f"{value:+.1f}"
    return f"{value:g}" if isinstance(value, float) else str(value)


MD_COLUMNS = (
    ("photos", "photos"),
    ("registered", "registered"),
    ("goals_reached", "goals reached"),
    ("completeness_2cm", "complete 2 cm"),
    ("accuracy_2cm", "accurate 2 cm"),
    ("fscore_2cm", "F 2 cm"),
    ("completeness_5cm", "complete 5 cm"),
    ("accuracy_5cm", "accurate 5 cm"),
    ("fscore_5cm", "F 5 cm"),
    ("seen_2", "seen by >= 2"),
    ("margin_random", "over random"),
    ("margin_frontier", "over frontier"),
)


def markdown(doc: dict) -> str:
    """``suite.md``: one row per scene, then the median and the worst scene."""
    units = {k: u for k, _, u in COLUMNS}

    def cells(row: dict) -> list[str]:
        out = []
        for key, _ in MD_COLUMNS:
            text = _fmt(row.get(key), units[key])
            if key == "goals_reached" and row.get("goals_reachable") is not None:
                text = f"{text} of {row['goals_reachable']}"
            if key == "registered" and row.get("photos") is not None:
                text = f"{text} of {row['photos']}"
            out.append(text)
        return out

    head = ["scene", *(label for _, label in MD_COLUMNS)]
    lines = [
        "# Scene suite",
        "",
        "Per scene: the adaptive campaign's final evaluation against the simulator's truth; "
        "goals: truly reachable goals reached within 10 cm; margins: dense completeness at "
        "2 cm over the random-exploration and frontier baselines at the same photo budget "
        "(points).",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    for row in doc["scenes"]:
        lines.append("| " + " | ".join([row["scene"], *cells(row)]) + " |")
    med = {k: v for k, v in doc["median"].items()}
    lines.append("| **median** | " + " | ".join(
        _fmt(med.get(k), units[k]) for k, _ in MD_COLUMNS) + " |")  # fmt: skip
    worst = doc["worst"]
    lines.append(f"| **worst: {worst['scene']}** | " + " | ".join(cells(worst)) + " |")
    lines += ["", f"The worst scene is the one least complete at 2 cm ({worst['scene']})."]
    return "\n".join(lines) + "\n"


def plot_suite(doc: dict, png: Path) -> Path:
    """Left: dense completeness at 2 cm per scene, adaptive against both baselines, with
    the median. Right: per scene, registered share, reachable goals reached, area seen by
    >= 2 photos and F at 2 cm."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    rows = doc["scenes"]
    names = [r["scene"] for r in rows]
    x = np.arange(len(rows))

    def values(key: str) -> np.ndarray:
        return np.array([np.nan if r.get(key) is None else 100 * r[key] for r in rows])

    fig, (ax_c, ax_q) = plt.subplots(1, 2, figsize=(max(10, 1.6 * len(rows) + 4), 4.6), dpi=100)
    width = 0.27
    for k, (key, label, color) in enumerate((
        ("completeness_2cm", "adaptive", "tab:red"),
        ("random_completeness_2cm", "random exploration", "tab:blue"),
        ("frontier_completeness_2cm", "frontier", "tab:green"),
    )):  # fmt: skip
        ax_c.bar(x + (k - 1) * width, values(key), width, label=label, color=color)
    med = doc["median"].get("completeness_2cm")
    if med is not None:
        ax_c.axhline(100 * med, color="tab:red", ls="--", lw=1, label="adaptive: median")
    ax_c.set_xticks(x, names, rotation=30, ha="right")
    ax_c.set_ylabel("dense completeness at 2 cm (%)")
    ax_c.set_ylim(0, 100)
    ax_c.set_title(f"completeness at 2 cm; worst scene: {doc['worst']['scene']}", fontsize=10)
    ax_c.legend(fontsize=8, loc="lower right")
    ax_c.grid(axis="y", alpha=0.3)
    for key, label in (
        ("registered_fraction", "photos registered"),
        ("goals_reached_fraction", "reachable goals reached (10 cm)"),
        ("seen_2", "observable area seen by >= 2 photos"),
        ("fscore_2cm", "F at 2 cm"),
    ):
        ax_q.plot(x, values(key), "o-", label=label, ms=6, lw=1)
    ax_q.set_xticks(x, names, rotation=30, ha="right")
    ax_q.set_ylim(0, 102)
    ax_q.set_ylabel("%")
    ax_q.set_title("per scene", fontsize=10)
    ax_q.legend(fontsize=8, loc="lower right")
    ax_q.grid(alpha=0.3)
    fig.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png)
    plt.close(fig)
    return png
