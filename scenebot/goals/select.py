"""Goals: the candidates with the poorest predicted rendering, kept diverse (``goals.json``)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np


def _ranked(score: np.ndarray, valid: np.ndarray | None) -> np.ndarray:
    """Indices of the allowed candidates with a finite score, highest score first (ties in
    index order)."""
    score = np.asarray(score, np.float64)
    ok = np.isfinite(score) if valid is None else (np.isfinite(score) & valid)
    idx = np.nonzero(ok)[0]
    return idx[np.argsort(-score[idx], kind="stable")]


def heading_difference(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Absolute difference of headings (rad), wrapped to [0, pi]."""
    return np.abs((np.asarray(a) - np.asarray(b) + np.pi) % (2 * np.pi) - np.pi)


def same_view(poses: np.ndarray, pose: np.ndarray, radius_m: float, angle_deg: float) -> np.ndarray:
    """(N,) bool: which of ``poses`` (N, 3) are closer than ``radius_m`` to ``pose`` (x, y,
    theta) AND within ``angle_deg`` of its heading: views a goal there already takes."""
    near = np.hypot(poses[:, 0] - pose[0], poses[:, 1] - pose[1]) < radius_m
    return near & (heading_difference(poses[:, 2], pose[2]) <= np.deg2rad(angle_deg))


def select_goals(
    poses: np.ndarray,
    score: np.ndarray,
    k: int,
    radius_m: float,
    angle_deg: float,
    valid: np.ndarray | None = None,
) -> np.ndarray:
    """Greedy non-maximum suppression: highest scores first, diverse in position and heading.

    A candidate is suppressed when an already chosen goal is closer than ``radius_m`` AND its
    heading differs by at most ``angle_deg``.

    Args:
        poses: (N, 3) x, y (m), theta (rad).
        score: (N,) view scores (degrees; higher = poorer predicted rendering); NaN is skipped.
        k: most goals.
        radius_m: suppression radius (m).
        angle_deg: suppression heading threshold (degrees).
        valid: (N,) bool, candidates allowed at all (default all).

    Returns:
        (<= k,) indices of the chosen candidates, best first.
    """
    idx = _ranked(score, valid)
    chosen: list[int] = []
    for c in idx:
        if len(chosen) == k:
            break
        if chosen and same_view(poses[chosen], poses[c], radius_m, angle_deg).any():
            continue
        chosen.append(int(c))
    return np.array(chosen, dtype=np.int64)


def view_directions(theta: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    """(N, 3) unit viewing directions of headings ``theta`` tilted up by ``pitch`` (rad)."""
    t, p = np.asarray(theta, float), np.asarray(pitch, float)
    return np.stack([np.cos(p) * np.cos(t), np.cos(p) * np.sin(t), np.sin(p)], axis=-1)


def select_goals_3d(
    poses: np.ndarray,
    score: np.ndarray,
    k: int,
    radius_m: float,
    angle_deg: float,
    valid: np.ndarray | None = None,
) -> np.ndarray:
    """:func:`select_goals` for a person's six-degree-of-freedom candidates: a candidate is
    suppressed when an already chosen goal is closer than ``radius_m`` in 3-D AND its viewing
    direction (heading and pitch) is within ``angle_deg`` of the goal's.

    Args:
        poses: (N, 5) x, y, z (m), theta, pitch (rad).
        score: (N,) view scores (degrees; higher = poorer predicted rendering); NaN is skipped.
        k: most goals.
        radius_m: suppression radius (m).
        angle_deg: suppression angle between viewing directions (degrees).
        valid: (N,) bool, candidates allowed at all (default all).

    Returns:
        (<= k,) indices of the chosen candidates, best first.
    """
    idx = _ranked(score, valid)
    dirs = view_directions(poses[:, 3], poses[:, 4])
    cos_thr = np.cos(np.deg2rad(angle_deg))
    chosen: list[int] = []
    for c in idx:
        if len(chosen) == k:
            break
        if chosen:
            near = np.linalg.norm(poses[chosen, :3] - poses[c, :3], axis=1) < radius_m
            same = dirs[chosen] @ dirs[c] >= cos_thr
            if (near & same).any():
                continue
        chosen.append(int(c))
    return np.array(chosen, dtype=np.int64)


def goals_document(
    poses: np.ndarray,
    score: np.ndarray,
    chosen: np.ndarray,
    threshold_deg: float,
    round_name: str,
    extra: dict | None = None,
) -> dict:
    """The ``goals.json`` content.

    ``complete`` is True when the best (highest) finite view score is below the threshold:
    every candidate view is predicted to render well from the photos already taken. In that
    case the goals are still listed (for information) but the workflow should stop exploring.

    Args:
        poses: (N, 3) a robot's candidate poses, or (N, 5) a person's (x, y, z, theta,
            pitch): their goals also give z and pitch.
        score: (N,) view scores (degrees).
        chosen: indices from :func:`select_goals`.
        threshold_deg: completeness threshold (degrees).
        round_name: e.g. ``"round_002"``.
        extra: more top-level fields (settings, counts).

    Returns:
        A JSON-serialisable dict.
    """
    finite = np.isfinite(score)
    best = float(np.max(score[finite])) if finite.any() else float("nan")
    person = poses.shape[1] == 5
    doc = {
        "round": round_name,
        "complete": bool(finite.any() and best < threshold_deg),
        "best_score_deg": None if not np.isfinite(best) else round(best, 4),
        "threshold_deg": threshold_deg,
        "n_candidates": len(score),
        "pose_convention": (
            "camera centre x, y, z (map frame), heading theta (rad, ccw from x) and pitch "
            "(rad, up positive), roll 0"
            if person
            else "camera centre x, y (m, map frame) and heading theta (rad, ccw from x)"
        ),
        "goals": [_goal(r, int(c), poses, score) for r, c in enumerate(chosen)],
    }
    if extra:
        doc.update(extra)
    return doc


def _goal(rank: int, c: int, poses: np.ndarray, score: np.ndarray) -> dict:
    """One goal of goals.json: a robot's x, y, theta, or a person's x, y, z, theta, pitch."""
    if poses.shape[1] == 5:
        x, y, z, t, p = (float(v) for v in poses[c])
        pose = {"x": round(x, 4), "y": round(y, 4), "z": round(z, 4), "theta": round(t, 5),
                "pitch": round(p, 5)}  # fmt: skip
    else:
        pose = {"x": round(float(poses[c, 0]), 4), "y": round(float(poses[c, 1]), 4),
                "theta": round(float(poses[c, 2]), 5)}  # fmt: skip
    return {"rank": rank, "candidate": c, **pose, "score_deg": round(float(score[c]), 4)}


def write_goals(path: str | Path, doc: dict) -> None:
    """Write ``goals.json``."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text(json.dumps(doc, indent=1))
