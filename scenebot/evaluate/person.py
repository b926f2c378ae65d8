"""A guided campaign's shots against the truth (``robot: guided``, ``person-sim``).

Per round r >= 1: which shots of round r-1's guide the photos fulfilled (the round's
``fulfilment.json``, written by the guide's fulfilment rule from the maps alone), and, where
the capture logs hold the simulated person's truth, how far the person truly stood from each
shot it aimed at: the shot of round r-1's ``goals.json`` is placed in the world by the
similarity that fits round r-1's map to the true camera centres (the evaluation's, not the
person's own reading of the map), and compared with the true camera of each photo taken for
it. ``person_error`` is the distance from where the person meant to stand (its own reading
of the guide) to where it truly stood: the walking error alone.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from scenebot.capturelog import photo_records
from scenebot.evaluate.metrics import EvaluationError, robot_to_world
from scenebot.geometry import view_direction
from scenebot.sfm.evaluate import summary_stats


def _heading_pitch(v: np.ndarray) -> tuple[float, float]:
    return math.atan2(v[1], v[0]), math.asin(float(np.clip(v[2], -1.0, 1.0)))


def person_shots(scene_dir: Path, captures: Sequence[Path], round_index: int) -> dict:
    """The shots of rounds 1..``round_index`` against the truth and the fulfilment files.

    Args:
        scene_dir: ``results/<scene>``.
        captures: capture folders (or their logs) of rounds 0..``round_index``.
        round_index: the last round evaluated.

    Returns:
        ``fulfilment`` (per round the summary of ``fulfilment.json``, and the totals:
        ``shots``, ``fulfilled``, ``fulfilled_fraction``), ``shots`` (per photo aimed at a
        shot: round, shot rank, image, ``true_distance_m`` to the shot, ``heading_error_deg``,
        ``pitch_error_deg``, ``person_error_m``), their summaries, and ``skipped`` (shots the
        simulated person could not stand at), ``notes``.
    """
    scene_dir = Path(scene_dir)
    caps = [Path(c) for c in captures]
    rounds, rows, notes, skipped = [], [], [], 0
    for k in range(1, round_index + 1):
        prev = scene_dir / f"round_{k - 1:03d}"
        ful = scene_dir / f"round_{k:03d}" / "fulfilment.json"
        if ful.is_file():
            rounds.append({"round": k, **json.loads(ful.read_text(encoding="utf-8"))["summary"]})
        sim_log = scene_dir / f"round_{k:03d}" / "capture" / "inbox" / "person-sim.jsonl"
        if sim_log.is_file():
            skipped += sum(
                1 for line in sim_log.read_text(encoding="utf-8").splitlines()
                if '"skipped"' in line
            )  # fmt: skip
        if k >= len(caps):
            continue
        aimed = [r for r in photo_records(_log(caps[k])) if "aimed_shot" in r and "truth" in r]
        if not aimed or not (prev / "goals.json").is_file():
            continue
        goals = {g["rank"]: g for g in json.loads((prev / "goals.json").read_text())["goals"]}
        try:
            sim = robot_to_world(prev / "sfm", caps[:k])
        except EvaluationError as exc:
            notes.append(f"round {k}: {exc}")
            continue
        for rec in aimed:
            g = goals.get(rec["aimed_shot"])
            if g is None:
                continue
            gw = sim.apply(np.array([[g["x"], g["y"], g.get("z", 0.0)]]))[0]
            gh, gp = _heading_pitch(sim.R @ view_direction(g["theta"], g.get("pitch", 0.0)))
            tr = rec["truth"]
            tc = np.asarray(tr["center"], float)
            th, tp = _heading_pitch(np.asarray(tr["R_cam_from_world"], float)[2])
            row = {
                "round": k,
                "shot": rec["aimed_shot"],
                "image": rec["image"],
                "true_distance_m": float(np.linalg.norm(tc - gw)),
                "heading_error_deg": abs(math.degrees(math.remainder(th - gh, 2 * math.pi))),
                "pitch_error_deg": abs(math.degrees(tp - gp)),
            }
            if "aimed" in tr:
                meant = np.asarray(tr["aimed"]["center"], float)
                row["person_error_m"] = float(np.linalg.norm(tc - meant))
            rows.append(row)
    shots = sum(r["shots"] for r in rounds)
    fulfilled = sum(r["fulfilled"] for r in rounds)

    def stats(key: str) -> dict:
        return summary_stats(np.array([r[key] for r in rows if key in r]))

    return {
        "fulfilment": {
            "rounds": rounds,
            "shots": shots,
            "fulfilled": fulfilled,
            "fulfilled_fraction": fulfilled / shots if shots else None,
        },
        "shots": rows,
        "true_distance_m": stats("true_distance_m"),
        "heading_error_deg": stats("heading_error_deg"),
        "pitch_error_deg": stats("pitch_error_deg"),
        "person_error_m": stats("person_error_m"),
        "skipped": skipped,
        "notes": notes,
    }


def _log(cap: Path) -> Path:
    return cap / "log.jsonl" if cap.is_dir() else cap
