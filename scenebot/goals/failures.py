"""What the robot failed at in earlier rounds: goals it abandoned, rounds it added nothing.

The map of round r is all the goals stage sees; it does not know that the robot already
drove toward a view and gave up (bumped into furniture the map lacks, could not localize,
found the goal inside an obstacle). A round whose goals were all abandoned adds no photo,
the map stays the same, and the score picks the same views again: the campaign spends its
rounds (a living room once spent three rounds on 30 abandoned goals, taking no photo).

A person's guided rounds have no capture log of goals: a shot of the guide that no photo
fulfilled (:func:`unfulfilled_shots`, from the round's ``fulfilment.json``) is its abandoned
goal; in the flat a person's guide asked for the same place beyond a wall four rounds in a
row, skipped each time.

Two uses of the capture logs of the adaptive rounds so far:

* **avoid**: candidates within ``goals.nms_radius_m`` of a goal abandoned in an earlier
  round are not chosen again (the same spacing the goals keep from each other: a view
  that close would be the same view); the backups of the plan stage are chosen the same way.
  If that leaves no candidate, the avoidance is dropped and the log says so.
* **stuck**: a round most of whose new photos did not join the map (:func:`is_idle`: of the
  photos the sfm stage saw for the first time, ``map_photos`` less the previous round's, the
  map's registered images grew by fewer than half; with no photo counts, a round that added
  no photo) is *idle*; ``goals.patience`` idle rounds in a row and the campaign stops, saying
  why (the rounds' photos that joined, the reasons the goals were abandoned), instead of
  running on to ``max_rounds`` or stopping as complete. A flat campaign once stopped as
  "complete" by diminishing returns after two rounds in which 6 and 3 of 25 photos joined
  the map (repeating wallpaper: the others registered metres off and were left out).
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


def unfulfilled_shots(fulfilment_json: Path | None) -> list[dict]:
    """A person's abandoned goals: the shots of the guides so far that no photo fulfilled
    (the round's ``fulfilment.json`` ``unfulfilled``, already in the round's map frame;
    :mod:`scenebot.guide.fulfil`), as :func:`abandoned_goals` gives a robot's. None without
    the file (round 0, a robot)."""
    if fulfilment_json is None or not Path(fulfilment_json).is_file():
        return []
    doc = json.loads(Path(fulfilment_json).read_text(encoding="utf-8"))
    return [
        {"round": str(u.get("round", "")), "x": float(u["x"]), "y": float(u["y"]),
         "reason": str(u.get("reason", "unfulfilled"))}
        for u in doc.get("unfulfilled", [])
    ]  # fmt: skip


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


#: a round is idle when its new photos grew the map by less than this share of them: most of
#: what it photographed is missing from the map, so the map's unchanged score says little
#: about what more photos would bring, and rounds like it are the campaign failing, not the
#: room being complete
IDLE_JOIN_SHARE = 0.5


def round_photos(
    map_images: int | None, map_photos: int | None, prev: dict
) -> tuple[int, int | None] | None:
    """What the round added: (photos that joined the map, new photos the sfm stage saw),
    from this round's registered images and photos and the previous round's goals.json
    (``prev``: its ``map_images``, ``map_photos``). The second is None without the photo
    counts; the whole is None without the registered images."""
    prev_images = prev.get("map_images")
    if map_images is None or prev_images is None:
        return None
    prev_photos = prev.get("map_photos")
    taken = None if map_photos is None or prev_photos is None else map_photos - prev_photos
    return map_images - prev_images, taken


def is_idle(joined: int, taken: int | None) -> bool:
    """Whether a round that took ``taken`` new photos, of which the map grew by ``joined``,
    is idle (:data:`IDLE_JOIN_SHARE`); without the photo count, whether it added none."""
    if taken is None or taken <= 0:
        return joined <= 0
    return joined < IDLE_JOIN_SHARE * taken


def idle_rounds(
    map_images: int | None, previous_goals_json: Path | None, abandoned: list[dict],
    patience: int, map_photos: int | None = None,
) -> dict | None:  # fmt: skip
    """Whether the campaign is stuck: the idle rounds in a row (:func:`is_idle`).

    Args:
        map_images: registered images of this round's map.
        previous_goals_json: the previous round's goals.json (its ``map_images``,
            ``map_photos`` and ``idle``), or None (round 0).
        abandoned: the goals abandoned so far (:func:`abandoned_goals`).
        patience: idle rounds in a row that make the campaign stuck (``goals.patience``).
        map_photos: the photos the round's sfm stage saw, every round's so far (its
            ``report.json``), or None.

    Returns:
        goals.json's ``idle``: ``rounds`` (in a row, this one included), this round's
        ``joined`` and ``new_photos``, ``history`` (joined and new photos of each idle round
        in the row), ``stuck`` and a ``reason`` when stuck; None without the figures to
        judge.
    """
    if map_images is None or previous_goals_json is None:
        return None
    path = Path(previous_goals_json)
    if not path.is_file():
        return None
    prev = json.loads(path.read_text(encoding="utf-8"))
    added = round_photos(map_images, map_photos, prev)
    if added is None:
        return None
    joined, taken = added
    idle = is_idle(joined, taken)
    before = prev.get("idle") or {}
    rounds = int(before.get("rounds", 0)) + 1 if idle else 0
    history = [*before.get("history", [])][-(rounds - 1) :] if rounds > 1 else []
    history = [*history, [joined, taken]] if idle else []
    out = {"rounds": rounds, "map_images": map_images, "previous_map_images": map_images - joined,
           "joined": joined, "new_photos": taken, "history": history, "patience": patience,
           "stuck": rounds >= patience}  # fmt: skip
    if out["stuck"]:
        why = Counter(_short_reason(a["reason"]) for a in abandoned)
        top = "; ".join(f"{n} x {r}" for r, n in why.most_common(3)) or "none abandoned"
        if all(t is None for _, t in history):
            what = "added no photo to the map"
        else:
            each = (f"{max(j, 0)} of {t}" if t is not None else str(max(j, 0)) for j, t in history)
            what = f"added to the map fewer than half their new photos ({', '.join(each)})"
        out["reason"] = (
            f"stuck: {rounds} rounds in a row {what} ({map_images - joined} -> {map_images} "
            f"registered; goals.patience = {patience}); goals abandoned so far: "
            f"{len(abandoned)} ({top})"
        )
    return out
