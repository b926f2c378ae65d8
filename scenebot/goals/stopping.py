"""The stopping rule: when is the map complete? One rule, read by the goals stage each round.

A round's map is **complete**, and the campaign takes no more rounds, when either holds:

1. **Nothing left to gain at any view** (the paper's rule): the best view score over the
   candidates a photo could be registered from is below ``goals.complete_threshold_deg``:
   every candidate view is predicted to render well from the photos already taken.
2. **Diminishing returns** (:func:`diminishing_returns`): for ``goals.patience`` rounds in a
   row, the round's photos moved the mean view score by less than ``goals.min_score_gain``
   (a fraction) *and* added less new free space (farther than ``goals.new_area_margin_m``
   from the previous round's) than ``goals.min_area_gain`` of the previous free area. An
   idle round (most of its new photos did not join the map) measured too little and does
   not count.

With ``goals.method: frontier`` (the baseline) the map is complete when no frontier is left.
Either way a campaign whose last ``goals.patience`` rounds were idle stops as *stuck*, saying
why (:mod:`scenebot.goals.failures`).
Whatever the rule says, the campaign stops after ``max_rounds`` rounds (``campaign.json``
says which of these stopped it).
"""

from __future__ import annotations

import json
from pathlib import Path

from scenebot.goals.failures import is_idle, round_photos


def diminishing_returns(
    mean_score: float | None,
    free_area_m2: float,
    previous_goals_json: Path | None,
    min_gain: float,
    min_area_gain: float,
    map_images: int | None = None,
    new_area_m2: float | None = None,
    *,
    patience: int,
    size_key: str = "free_area_m2",
    map_photos: int | None = None,
) -> dict | None:
    """What the last round bought, and whether that is too little to go on.

    Two measures, each against the previous round's ``goals.json``: the mean view score over
    the candidates (the predicted rendering error averaged over the free space) and the free
    space. Photos of known space lower the mean; photos that open space the map did not know
    (another room behind a doorway) add free space, and raise the mean while the new space is
    still unphotographed. The map is complete when the mean moved by less than ``min_gain``
    (a fraction of the previous mean) either way *and* the new free space (``new_area_m2``:
    this round's free space away from the previous round's; without it, the net growth of
    the free area) is less than ``min_area_gain`` of the previous free area. The net growth
    alone misses a corridor that opens while the map's walls close in elsewhere. None for
    round 0 (no previous ``goals.json``) or when a measure is missing. ``size_key``: the
    goals.json key of the free space's size (a person's map: ``free_volume_m3``).

    One round's gain is noisy, so the map is complete only when the gain was that low in
    ``patience`` consecutive rounds (``low_rounds`` counts them; the previous round's count
    comes from its ``goals.json``).

    An idle round (:func:`scenebot.goals.failures.is_idle`: most of its new photos did not
    join the map, from ``map_images``, the registered images, and ``map_photos``, the photos
    the sfm stage saw; without the photo counts, a round that added no photo) measured too
    little to show diminishing returns: the test is not applied, and the next round tries
    again (rounds like it make the campaign stuck instead).
    """
    if mean_score is None or previous_goals_json is None or not previous_goals_json.is_file():
        return None
    prev_doc = json.loads(previous_goals_json.read_text(encoding="utf-8"))
    prev, prev_area = prev_doc.get("mean_score_deg"), prev_doc.get(size_key)
    if not prev or not prev_area:
        return None
    gain = (prev - mean_score) / prev
    area_gain = (free_area_m2 - prev_area) / prev_area
    new_gain = None if new_area_m2 is None else new_area_m2 / prev_area
    grew = area_gain if new_gain is None else new_gain
    out = {"previous_mean_score_deg": prev, "mean_score_deg": round(mean_score, 4),
           "gain": round(gain, 4), "min_gain": min_gain,
           "previous_free_area_m2": prev_area, "free_area_m2": round(free_area_m2, 4),
           "area_gain": round(area_gain, 4), "min_area_gain": min_area_gain,
           "new_area_m2": None if new_area_m2 is None else round(new_area_m2, 4),
           "new_area_gain": None if new_gain is None else round(new_gain, 4)}  # fmt: skip
    prev_low = int((prev_doc.get("score_gain") or {}).get("low_rounds", 0))
    added = round_photos(map_images, map_photos, prev_doc)
    no_photo = added is not None and is_idle(*added)
    if added is not None:
        out["map_images"], out["previous_map_images"] = map_images, map_images - added[0]
    if no_photo and (added[1] is None or added[0] <= 0):
        out["not_applied"] = (
            f"the last round added no photo to the map ({map_images - added[0]} -> "
            f"{map_images} registered images: its goals were not reached), so no change in "
            "the score says nothing about what more photos would bring"
        )
    elif no_photo:
        out["not_applied"] = (
            f"the last round added {added[0]} of its {added[1]} new photos to the map "
            f"({map_images - added[0]} -> {map_images} registered images; the others did not "
            "register or were left out), so its change in the score says little about what "
            "more photos would bring"
        )
    out["low"] = bool(not no_photo and min_gain > 0 and abs(gain) < min_gain
                      and grew < min_area_gain)  # fmt: skip
    out["low_rounds"] = prev_low + 1 if out["low"] else (prev_low if no_photo else 0)
    out["patience"] = patience
    out["complete"] = not no_photo and out["low_rounds"] >= max(patience, 1)
    if out["complete"]:
        out["reason"] = (
            f"diminishing returns: since the previous round the mean view score changed by "
            f"{-100 * gain:+.1f}% ({prev:.1f} -> {mean_score:.1f} deg; goals.min_score_gain "
            f"= {100 * min_gain:.0f}%) and the free space by {100 * area_gain:+.1f}% "
            f"({prev_area:.1f} -> {free_area_m2:.1f} m^2"
            + ("" if new_area_m2 is None else f", {new_area_m2:.2f} m^2 of it new")
            + f"; goals.min_area_gain = {100 * min_area_gain:.0f}%"
            + ("" if size_key == "free_area_m2" else f", of {size_key}")
            + ")"
            + ("" if patience <= 1 else f", {out['low_rounds']} rounds in a row "
               f"(goals.patience = {patience})")
        )  # fmt: skip
    return out


def apply_stopping_rule(doc: dict, returns: dict | None, threshold_deg: float) -> None:
    """Set ``doc["complete"]`` and ``doc["complete_because"]`` (the goals.json document, whose
    ``complete`` already says whether rule 1 holds) from rules 1 and 2."""
    if returns is not None and returns["complete"] and not doc["complete"]:
        doc["complete"] = True
        doc["complete_because"] = returns["reason"]
    elif doc["complete"]:
        doc["complete_because"] = (
            f"best view score {doc['best_score_deg']} deg < goals.complete_threshold_deg "
            f"= {threshold_deg}"
        )
