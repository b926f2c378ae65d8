"""Which photo pairs to match: a number of pairs that grows linearly with the photo count.

Sources of pairs (union, each pair once):

* **exhaustive** for small sets (``exhaustive_max_images``);
* **spatial**: for each photo the ``spatial_neighbors`` best photos by logged position and
  heading in the same frame (previous map, visual localization, or the round's odometry).
  The score ``distance_m + 3 m/rad * heading_difference`` prefers photos that look the same
  way from nearby, so circles of photos taken at one spot also pair with other spots;
* **heading bridge**: photos whose position is in no frame shared with other photos (a new
  round without localization) pair with photos of other frames facing within 30 degrees
  (compass headings are absolute);
* **sequential**: the next ``sequential_overlap`` photos of the same round;
* **loop closure**: ``loop_closure_pairs`` partners per photo spread evenly over the first
  round's photos (for a photo of the first round) or over the photos of the rounds before
  its own (for a later round's photo): a photo's partners are fixed once its round is taken,
  so the pairs of photos already matched never change when a round adds photos. (Spread
  over the whole set, every photo's partners moved each round: in the default office
  campaign's round 3 the loop pairs were 525 of the 949 pairs matched, mostly between photos
  already mapped. Spread over the photos *before* each one in capture order, round 0 of the
  flat folded: 5 of 100 photos registered, against 99 with the first round's pairs as before.)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

HEADING_WEIGHT_M_PER_RAD = 3.0
MAX_HEADING_DIFF_RAD = math.radians(100.0)
BRIDGE_HEADING_DIFF_RAD = math.radians(30.0)


@dataclass(frozen=True)
class PairPrior:
    """What is known about where a photo was taken, for pair selection.

    Attributes:
        name: photo name.
        round: capture round.
        index: order within the round.
        frame: name of the frame ``xy`` is in (``"robot"`` for map/localization estimates,
            ``"odometry_{round}"`` for odometry), or ``None`` when unknown.
        xy: position (m) in ``frame`` or ``None``.
        heading: absolute heading (rad, compass-referenced) or ``None``.
    """

    name: str
    round: int
    index: int
    frame: str | None = None
    xy: tuple[float, float] | None = None
    heading: float | None = None


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


def select_pairs(
    priors: list[PairPrior],
    *,
    exhaustive_max_images: int,
    spatial_neighbors: int,
    spatial_max_distance_m: float,
    sequential_overlap: int,
    loop_closure_pairs: int,
) -> dict[str, set[tuple[str, str]]]:
    """Select pairs to match.

    Args:
        priors: one per photo, in capture order.
        exhaustive_max_images: sets up to this size get all pairs.
        spatial_neighbors: neighbours per photo by position and heading.
        spatial_max_distance_m: farthest spatial neighbour (m).
        sequential_overlap: next photos of the same round paired with each photo.
        loop_closure_pairs: evenly spread long-range pairs per photo.

    Returns:
        ``{source: {(name_a, name_b), ...}}`` with ``name_a < name_b``; sources
        ``exhaustive``, ``spatial``, ``bridge``, ``sequential``, ``loop``.
    """
    n = len(priors)
    out: dict[str, set[tuple[str, str]]] = {
        k: set() for k in ("exhaustive", "spatial", "bridge", "sequential", "loop")
    }

    def add(src: str, i: int, j: int) -> None:
        if i != j:
            a, b = priors[i].name, priors[j].name
            out[src].add((a, b) if a < b else (b, a))

    if n <= exhaustive_max_images:
        for i in range(n):
            for j in range(i + 1, n):
                add("exhaustive", i, j)
        return out

    # sequential, within a round
    by_round: dict[int, list[int]] = {}
    for i, p in enumerate(priors):
        by_round.setdefault(p.round, []).append(i)
    ordered = {r: sorted(by_round[r], key=lambda i: priors[i].index) for r in sorted(by_round)}
    for members in ordered.values():
        for a in range(len(members)):
            for b in range(a + 1, min(a + 1 + sequential_overlap, len(members))):
                add("sequential", members[a], members[b])

    # loop closure: the first round's photos spread over that round, a later round's over
    # the rounds before it (fixed once the round is taken)
    earlier: list[int] = []
    for r, members in ordered.items():
        pool = earlier or members
        m = len(pool)
        for a, i in enumerate(members if m > 1 else []):
            for k in range(1, loop_closure_pairs + 1):
                add("loop", i, pool[(a + (k * m) // (loop_closure_pairs + 1)) % m])
        earlier = earlier + by_round[r]

    heading = np.array([np.nan if p.heading is None else p.heading for p in priors])
    frames: dict[str, list[int]] = {}
    for i, p in enumerate(priors):
        if p.frame is not None and p.xy is not None:
            frames.setdefault(p.frame, []).append(i)

    # spatial, within each frame
    for members in frames.values():
        idx = np.array(members)
        xy = np.array([priors[i].xy for i in members], dtype=float)
        hd = heading[idx]
        for a, i in enumerate(members):
            dist = np.linalg.norm(xy - xy[a], axis=1)
            dh = np.abs(_wrap(hd - hd[a]))
            dh = np.where(np.isnan(dh), 0.0, dh)
            score = dist + HEADING_WEIGHT_M_PER_RAD * dh
            ok = (dist <= spatial_max_distance_m) & (dh <= MAX_HEADING_DIFF_RAD)
            ok[a] = False
            cand = np.flatnonzero(ok)
            for b in cand[np.argsort(score[cand], kind="stable")][:spatial_neighbors]:
                add("spatial", i, int(idx[b]))

    # heading bridge for photos whose frame no other round shares
    for i, p in enumerate(priors):
        shared = p.frame is not None and any(
            priors[j].round != p.round for j in frames.get(p.frame, [])
        )
        if shared or np.isnan(heading[i]):
            continue
        others = [
            j
            for j in range(n)
            if priors[j].round != p.round
            and not np.isnan(heading[j])
            and abs(_wrap(heading[j] - heading[i])) <= BRIDGE_HEADING_DIFF_RAD
        ]
        if not others:
            continue
        take = np.linspace(0, len(others) - 1, min(spatial_neighbors, len(others)))
        for t in np.unique(np.round(take).astype(int)):
            add("bridge", i, others[t])
    return out
