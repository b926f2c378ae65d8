"""Where a person stands for each advised shot: the photo already taken nearest to the shot,
and the step from there in that photo's own terms (forward, to the right, up; turn, tilt).

A person remembers where they stood for a photo and which way they faced; "from there, two
steps forward and a little to the right, turn left a quarter" is advice they can follow
without a map. Lengths are in the map's units: metres when ``sfm.known_distance`` gave the
scale, else SfM units (the page says which).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

TIE_DISTANCE = 0.1
"""Photos within this share of the nearest one's distance count as equally near: of those,
the one facing most like the shot is the one to start from."""


def photo_poses(R: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """Photos as a person's poses: centre, heading and pitch of the optical axis (roll
    dropped).

    Args:
        R: (S, 3, 3) cam_from_world rotations.
        centres: (S, 3) camera centres.

    Returns:
        (S, 5) x, y, z, theta (rad, ccw from x), pitch (rad, up positive).
    """
    fwd = np.asarray(R, np.float64)[:, 2]  # each photo's optical axis in the map frame
    theta = np.arctan2(fwd[:, 1], fwd[:, 0])
    pitch = np.arcsin(np.clip(fwd[:, 2], -1.0, 1.0))
    return np.column_stack([np.asarray(centres, np.float64), theta, pitch])


def _directions(poses: np.ndarray) -> np.ndarray:
    t, p = poses[:, 3], poses[:, 4]
    return np.stack([np.cos(p) * np.cos(t), np.cos(p) * np.sin(t), np.sin(p)], axis=-1)


def nearest_photo(shot: np.ndarray, taken: np.ndarray) -> int:
    """The photo to start from: the nearest camera centre; among those within
    :data:`TIE_DISTANCE` of the nearest, the one whose view is closest to the shot's.

    Args:
        shot: (5,) x, y, z, theta, pitch.
        taken: (S, 5) the photos taken (S >= 1).

    Returns:
        Index into ``taken``.
    """
    d = np.linalg.norm(taken[:, :3] - shot[None, :3], axis=1)
    near = np.nonzero(d <= d.min() * (1 + TIE_DISTANCE) + 1e-12)[0]
    cos = _directions(taken[near]) @ _directions(shot[None])[0]
    return int(near[np.argmax(cos)])


@dataclass(frozen=True)
class Step:
    """The step from a photo taken to a shot, in the photo's levelled frame.

    Attributes:
        forward: along the photo's heading (map units; negative: back).
        right: to the right of that heading (negative: left).
        up: up (negative: down).
        distance: straight-line distance between the camera centres.
        turn_deg: heading change (degrees, positive: turn left), in (-180, 180].
        pitch_deg: the shot's tilt (degrees above level; negative: below).
        photo_pitch_deg: the photo's tilt, for comparison.
    """

    forward: float
    right: float
    up: float
    distance: float
    turn_deg: float
    pitch_deg: float
    photo_pitch_deg: float

    def as_dict(self, digits: int = 3) -> dict:
        return {k: round(float(v), digits) for k, v in asdict(self).items()}


def step_from(photo: np.ndarray, shot: np.ndarray) -> Step:
    """The step from ``photo`` to ``shot`` (both (5,) x, y, z, theta, pitch)."""
    th = float(photo[3])
    d = np.asarray(shot[:3], np.float64) - np.asarray(photo[:3], np.float64)
    forward = float(d[0] * np.cos(th) + d[1] * np.sin(th))
    right = float(d[0] * np.sin(th) - d[1] * np.cos(th))
    turn = (float(shot[3]) - th + np.pi) % (2 * np.pi) - np.pi
    if turn <= -np.pi + 1e-12:
        turn = np.pi
    return Step(forward, right, float(d[2]), float(np.linalg.norm(d)), float(np.degrees(turn)),
                float(np.degrees(shot[4])), float(np.degrees(photo[4])))  # fmt: skip


def _length(value: float, unit: str) -> str:
    return f"{value:.2f} m" if unit == "m" else f"{value:.2f} units"


def describe(step: Step, photo_name: str, unit: str) -> str:
    """The step in words, e.g. "Stand where you took IMG_3.jpg, facing as in it; then go
    0.40 m forward and 0.10 m right, 0.05 m higher (0.42 m from there); turn 30° left; aim
    10° above level."

    Args:
        step: from :func:`step_from`.
        photo_name: the photo's file name.
        unit: "m" (metric map) or anything else (SfM units).
    """
    small = max(0.1 * step.distance, 1e-9)  # parts under a tenth of the step are left out
    moves = [
        f"{_length(abs(v), unit)} {pos if v > 0 else neg}"
        for v, pos, neg in (
            (step.forward, "forward", "back"),
            (step.right, "right", "left"),
            (step.up, "higher", "lower"),
        )
        if abs(v) >= small
    ]
    parts = [f"Stand where you took {photo_name}, facing as in it"]
    if moves:
        parts.append(f"then go {', '.join(moves)} ({_length(step.distance, unit)} from there)")
    else:
        parts.append("stay there")
    if abs(step.turn_deg) >= 5:
        parts.append(f"turn {abs(step.turn_deg):.0f}° {'left' if step.turn_deg > 0 else 'right'}")
    else:
        parts.append("keep facing the same way")
    if abs(step.pitch_deg) < 3:
        parts.append("hold the camera level")
    else:
        where = "above" if step.pitch_deg > 0 else "below"
        parts.append(f"aim {abs(step.pitch_deg):.0f}° {where} level")
    return "; ".join(parts) + "."
