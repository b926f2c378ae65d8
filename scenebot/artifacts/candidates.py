"""``candidates.csv``: the score stage's scored candidate viewpoints, which the goals stage and
the score-validity study read.

A candidate is a camera centre x, y, z (m), a heading theta (rad, counter-clockwise from x)
and a pitch (rad, up positive), roll 0: a robot's candidates have z = 0 (the camera plane of
its map) and the pitch of its camera's mount (:func:`scenebot.geometry.mount_pitch`, 0 for a
level camera); a person's (``robot: photos``) use all five.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

CSV_COLUMNS = (
    "x",
    "y",
    "z",
    "theta",
    "pitch",
    "score_deg",
    "hit_fraction",
    "seen_fraction",
    "matchable_points",
)
POSE_COLUMNS = CSV_COLUMNS[:5]
PLANAR_COLUMNS = ("x", "y", "theta", *CSV_COLUMNS[5:])
"""The header before z and pitch (a robot's candidates): still read, as z = 0 and pitch 0."""


def write_candidates(path: str | Path, poses: np.ndarray, cols: dict[str, np.ndarray]) -> None:
    """Write ``candidates.csv`` (header + one row per candidate).

    Args:
        path: output path.
        poses: (N, 3) a robot's x, y (m), theta (rad), written with z = 0 and pitch 0; or
            (N, 5) x, y, z (m), theta, pitch (rad).
        cols: ``score_deg``, ``hit_fraction``, ``seen_fraction``, ``matchable_points``
            arrays (N,).
    """
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    poses = np.asarray(poses, np.float64)
    if poses.shape[1] == 3:
        zero = np.zeros(len(poses))
        poses = np.column_stack([poses[:, 0], poses[:, 1], zero, poses[:, 2], zero])
    data = np.column_stack([poses] + [np.asarray(cols[c], np.float64) for c in CSV_COLUMNS[5:]])
    np.savetxt(path, data, delimiter=",", header=",".join(CSV_COLUMNS), comments="", fmt="%.6g")


def read_candidates(path: str | Path) -> dict[str, np.ndarray]:
    """Read ``candidates.csv`` into columns (see :data:`CSV_COLUMNS`; a file with the older
    header :data:`PLANAR_COLUMNS` reads with z = 0 and pitch = 0)."""
    if not Path(path).exists():
        raise FileNotFoundError(f"{path}: no candidates; run the score stage for this round")
    lines = Path(path).read_text().splitlines()
    header = lines[0].split(",") if lines else []
    if header not in (list(CSV_COLUMNS), list(PLANAR_COLUMNS)):
        raise ValueError(f"{path}: header {header} is not {list(CSV_COLUMNS)}")
    if len(lines) < 2:
        return {c: np.zeros(0) for c in CSV_COLUMNS}
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    cols = {c: data[:, k] for k, c in enumerate(header)}
    for c in ("z", "pitch"):
        cols.setdefault(c, np.zeros(len(data)))
    return {c: cols[c] for c in CSV_COLUMNS}
