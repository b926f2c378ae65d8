"""Random candidate viewpoints inside the free space (written as ``candidates.csv`` with
:mod:`scenebot.artifacts.candidates`).
"""

from __future__ import annotations

import numpy as np

from scenebot.artifacts.freespace import FreeSpace, FreeSpaceError


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
