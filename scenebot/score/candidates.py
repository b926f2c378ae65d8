"""Random candidate viewpoints inside the free space, and the ``candidates.csv`` file."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scenebot.score.freespace import FreeSpace, FreeSpaceError

CSV_COLUMNS = (
    "x",
    "y",
    "theta",
    "score_deg",
    "hit_fraction",
    "seen_fraction",
    "matchable_points",
)
"""Columns of candidates.csv: x, y (m), theta (rad), score (deg), fractions (0..1)."""


def sample_candidates(fs: FreeSpace, n: int, rng: np.random.Generator, where: str) -> np.ndarray:
    """Uniform random poses in free space with uniform random headings.

    Positions are drawn uniformly over the free cells (jittered inside the cell) and kept when
    their exact distance to the cut mesh is at least the robot radius.

    Args:
        fs: the free space.
        n: number of candidates (> 0).
        rng: random generator.
        where: round name for error messages.

    Returns:
        (n, 3) poses (x m, y m, theta rad in [-pi, pi)).

    Raises:
        FreeSpaceError: zero candidates asked for, or none can be placed.
    """
    if n <= 0:
        raise FreeSpaceError(f"{where}: score.n_candidates is {n}; set it to at least 1")
    jj, ii = np.nonzero(fs.mask)
    if len(jj) == 0:
        raise FreeSpaceError(
            f"{where}: the free space is empty, no candidate can be placed; see the mesh stage's "
            "freespace.png, lower mesh.robot_radius_m or capture more photos"
        )
    out = np.zeros((0, 2))
    for _ in range(20):
        k = rng.integers(0, len(jj), size=2 * (n - len(out)) + 16)
        xy = fs.origin + (np.stack([ii[k], jj[k]], 1) + rng.random((len(k), 2))) * fs.resolution
        xy = xy[fs.contains(xy)]
        out = np.concatenate([out, xy])[:n]
        if len(out) == n:
            break
    if len(out) < n:
        raise FreeSpaceError(
            f"{where}: only {len(out)} of {n} candidates fit in the free space "
            f"({fs.area_m2:.3f} m^2); lower mesh.robot_radius_m or score.n_candidates"
        )
    theta = rng.uniform(-np.pi, np.pi, size=n)
    return np.concatenate([out, theta[:, None]], axis=1)


def write_candidates(path: str | Path, poses: np.ndarray, cols: dict[str, np.ndarray]) -> None:
    """Write ``candidates.csv`` (header + one row per candidate).

    Args:
        path: output path.
        poses: (N, 3) x, y (m), theta (rad).
        cols: ``score_deg``, ``hit_fraction``, ``seen_fraction``, ``matchable_points``
            arrays (N,).
    """
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    data = np.column_stack([poses] + [np.asarray(cols[c], np.float64) for c in CSV_COLUMNS[3:]])
    np.savetxt(path, data, delimiter=",", header=",".join(CSV_COLUMNS), comments="", fmt="%.6g")


def read_candidates(path: str | Path) -> dict[str, np.ndarray]:
    """Read ``candidates.csv`` into columns (see :data:`CSV_COLUMNS`)."""
    if not Path(path).exists():
        raise FileNotFoundError(f"{path}: no candidates; run the score stage for this round")
    lines = Path(path).read_text().splitlines()
    header = lines[0].split(",") if lines else []
    if header != list(CSV_COLUMNS):
        raise ValueError(f"{path}: header {header} is not {list(CSV_COLUMNS)}")
    if len(lines) < 2:
        return {c: np.zeros(0) for c in CSV_COLUMNS}
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return {c: data[:, k] for k, c in enumerate(CSV_COLUMNS)}
