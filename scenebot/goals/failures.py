"""What the robot failed at in earlier rounds: goals it abandoned, rounds it added nothing.

The map of round r is all the goals stage sees; it does not know that the robot already
drove toward a view and gave up (bumped into furniture the map lacks, could not localize,
found the goal inside an obstacle). A round whose goals were all abandoned adds no photo,
the map stays the same, and the score picks the same views again: the campaign spends its
rounds (a living room once spent three rounds on 30 abandoned goals, taking no photo).

Two uses of the capture logs of the adaptive rounds so far:

* **avoid**: candidates within ``goals.nms_radius_m`` of a goal abandoned in an earlier
  round are not chosen again (the same spacing the goals keep from each other: a view
  that close would be the same view); the backups of the plan stage are chosen the same way.
  If that leaves no candidate, the avoidance is dropped and the log says so.
* **stuck**: a round that added no photo to the map (``map_images`` no more than the previous
  round's) is *idle*; ``goals.patience`` idle rounds in a row and the campaign stops, saying
  why (the reasons the goals were abandoned), instead of running on to ``max_rounds``.
"""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import numpy as np


def abandoned_goals(capture_logs: list[Path]) -> list[dict]:
    """Goals abandoned in the given capture logs: ``{"round", "x", "y", "reason"}`` (map
    frame, m). Missing logs are skipped (a round not driven yet)."""
    out = []
    for path in capture_logs:
        path = Path(path)
        if not path.is_file():
            continue
        rnd = path.parent.parent.name
        for line in path.read_text(encoding="utf-8").splitlines():
            try:
                rec = json.loads(line)
            except json.JSONDecodeError:
                continue  # a torn last line of an interrupted round
            goal = rec.get("goal") or {}
            if rec.get("event") == "goal_abandoned" and "x" in goal and "y" in goal:
                out.append(
                    {"round": rnd, "x": float(goal["x"]), "y": float(goal["y"]),
                     "reason": str(rec.get("reason", ""))}
                )  # fmt: skip
    return out


def near_abandoned(xy: np.ndarray, abandoned: list[dict], radius_m: float) -> np.ndarray:
    """(N,) bool: which points lie within ``radius_m`` of an abandoned goal."""
    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    if not abandoned or radius_m <= 0:
        return np.zeros(len(xy), bool)
    g = np.array([[a["x"], a["y"]] for a in abandoned])
    d2 = ((xy[:, None, :] - g[None, :, :]) ** 2).sum(-1)
    return (d2 <= radius_m**2).any(axis=1)


def _short_reason(reason: str) -> str:
    """The first clause of an abandonment reason (counts group alike reasons)."""
    return reason.split(":")[0].strip() or "no reason logged"


def idle_rounds(
    map_images: int | None, previous_goals_json: Path | None, abandoned: list[dict],
    patience: int,
) -> dict | None:  # fmt: skip
    """Whether the campaign is stuck: the rounds in a row that added no photo to the map.

    Args:
        map_images: registered images of this round's map.
        previous_goals_json: the previous round's goals.json (its ``map_images`` and
            ``idle_rounds``), or None (round 0).
        abandoned: the goals abandoned so far (:func:`abandoned_goals`).
        patience: idle rounds in a row that make the campaign stuck (``goals.patience``).

    Returns:
        goals.json's ``idle``: ``rounds`` (in a row, this one included), ``stuck`` and a
        ``reason`` when stuck; None without the figures to judge.
    """
    if map_images is None or previous_goals_json is None:
        return None
    path = Path(previous_goals_json)
    if not path.is_file():
        return None
    prev = json.loads(path.read_text(encoding="utf-8"))
    prev_images = prev.get("map_images")
    if prev_images is None:
        return None
    idle = map_images <= prev_images
    before = int((prev.get("idle") or {}).get("rounds", 0))
    rounds = before + 1 if idle else 0
    out = {"rounds": rounds, "map_images": map_images, "previous_map_images": prev_images,
           "patience": patience, "stuck": rounds >= patience}  # fmt: skip
    if out["stuck"]:
        why = Counter(_short_reason(a["reason"]) for a in abandoned)
        top = "; ".join(f"{n} x {r}" for r, n in why.most_common(3)) or "none abandoned"
        out["reason"] = (
            f"stuck: {rounds} rounds in a row added no photo to the map ({prev_images} -> "
            f"{map_images} registered; goals.patience = {patience}); goals abandoned so far: "
            f"{len(abandoned)} ({top})"
        )
    return out
