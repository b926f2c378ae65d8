"""``candidates.csv``: the score stage's scored candidate viewpoints, which the goals stage and
the score-validity study read.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

CSV_COLUMNS = (
    "x",
    "y",
    "theta",
    "score_deg",
    "hit_fraction",
    "seen_fraction",
    "matchable_points",
)


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
