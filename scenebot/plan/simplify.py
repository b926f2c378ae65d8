"""Path simplification (paper section IV.B).

1. Merge runs of moves at the same angle into single longer moves (:func:`merge_runs`).
2. Recursively remove nodes that can be skipped: the straight move from node ``a`` to node
   ``b`` replaces the original moves between them when its cost is at most ``factor`` times
   the cost of those original moves; otherwise the span is split at the node farthest from
   the straight line and both halves are simplified the same way (:func:`simplify_path`).

Each kept segment costs at most ``factor`` times the original moves it replaces, so the
simplified path costs at most ``factor`` times the A* path; start and goal are always kept.

The cost of a straight move from cell ``p`` to cell ``q`` is its length times the mean cost per
metre of the cells of the digital line from ``p`` to ``q`` (``max(|dx|, |dy|)`` samples, start
excluded). For a move along one of the 8 directions this is exactly the A* cost of the run.
"""

from __future__ import annotations

import math

import numpy as np


def merge_runs(cells: np.ndarray) -> np.ndarray:
    """Indices of the nodes left after merging runs of same-direction moves.

    Args:
        cells: (K, 2) ``[iy, ix]`` consecutive 8-neighbour cells.

    Returns:
        (M,) int64 increasing indices into ``cells``: the first and last cell and every cell
        where the move direction changes.
    """
    cells = np.asarray(cells, np.int64)
    k = len(cells)
    if k <= 2:
        return np.arange(k, dtype=np.int64)
    step = np.diff(cells, axis=0)
    turn = np.any(step[1:] != step[:-1], axis=1)
    inner = np.nonzero(turn)[0] + 1
    return np.concatenate([[0], inner, [k - 1]]).astype(np.int64)


def line_cells(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Cells of the digital line from ``p`` to ``q`` (start excluded, end included).

    Args:
        p: (2,) start cell ``[iy, ix]``.
        q: (2,) end cell.

    Returns:
        (n, 2) int64 cells, ``n = max(|dy|, |dx|)``.
    """
    p = np.asarray(p, float)
    q = np.asarray(q, float)
    n = int(np.abs(q - p).max())
    if n == 0:
        return np.zeros((0, 2), np.int64)
    t = np.arange(1, n + 1, dtype=float)[:, None] / n
    return np.rint(p + (q - p) * t).astype(np.int64)


def segment_cost(p: np.ndarray, q: np.ndarray, cost_per_m: np.ndarray, cell_m: float) -> float:
    """Cost of driving straight from cell ``p`` to cell ``q`` (see the module docstring)."""
    cells = line_cells(p, q)
    if len(cells) == 0:
        return 0.0
    length = cell_m * math.hypot(float(q[0] - p[0]), float(q[1] - p[1]))
    return length * float(cost_per_m[cells[:, 0], cells[:, 1]].mean())


def cumulative_cost(cells: np.ndarray, cost_per_m: np.ndarray, cell_m: float) -> np.ndarray:
    """Cost of the original moves from ``cells[0]`` to each ``cells[i]``.

    Returns:
        (K,) float64, first entry 0.
    """
    cells = np.asarray(cells, np.int64)
    if len(cells) < 2:
        return np.zeros(len(cells))
    step = np.diff(cells, axis=0)
    length = np.where(np.abs(step).sum(axis=1) == 2, math.sqrt(2.0), 1.0) * cell_m
    return np.concatenate([[0.0], np.cumsum(length * cost_per_m[cells[1:, 0], cells[1:, 1]])])


def _farthest_from_chord(pts: np.ndarray) -> int:
    """Index (1..len-2) of the interior point farthest from the chord first-last."""
    a, b = pts[0], pts[-1]
    d = b - a
    norm = math.hypot(float(d[0]), float(d[1]))
    rel = pts[1:-1] - a
    if norm == 0.0:
        dist = np.hypot(rel[:, 0], rel[:, 1])
    else:
        dist = np.abs(rel[:, 0] * d[1] - rel[:, 1] * d[0]) / norm
    return int(np.argmax(dist)) + 1


def simplify_path(
    cells: np.ndarray, cost_per_m: np.ndarray, cell_m: float = 1.0, factor: float = 1.1
) -> np.ndarray:
    """Simplify an A* path: merge same-angle runs, then drop skippable nodes recursively.

    Args:
        cells: (K, 2) ``[iy, ix]`` A* path (consecutive 8-neighbours).
        cost_per_m: (ny, nx) cost per metre used by the search (with lethal penalties, see
            :func:`scenebot.plan.astar.effective_cost`), so that a shortcut through an
            obstacle is never taken.
        cell_m: cell edge length (m).
        factor: allowed cost ratio of a shortcut to the moves it replaces (>= 1).

    Returns:
        (M,) int64 increasing indices into ``cells`` of the kept nodes; first and last kept.
    """
    if factor < 1.0:
        raise ValueError(f"simplify_path: factor must be >= 1, got {factor}")
    cells = np.asarray(cells, np.int64)
    nodes = merge_runs(cells)
    if len(nodes) <= 2:
        return nodes
    cum = cumulative_cost(cells, cost_per_m, cell_m)
    node_pts = cells[nodes].astype(float)
    keep = np.zeros(len(nodes), bool)
    keep[0] = keep[-1] = True
    stack = [(0, len(nodes) - 1)]
    while stack:  # recursion written as a stack: (first, last) spans of node indices
        i, j = stack.pop()
        if j - i < 2:
            continue
        a, b = nodes[i], nodes[j]
        original = cum[b] - cum[a]
        if segment_cost(cells[a], cells[b], cost_per_m, cell_m) <= factor * original + 1e-12:
            continue  # every node strictly between i and j is skipped
        k = i + _farthest_from_chord(node_pts[i : j + 1])
        keep[k] = True
        stack.append((i, k))
        stack.append((k, j))
    return nodes[keep]


def polyline_cost(
    cells: np.ndarray, node_idx: np.ndarray, cost_per_m: np.ndarray, cell_m: float = 1.0
) -> float:
    """Cost of the straight segments through ``cells[node_idx]`` (see :func:`segment_cost`)."""
    pts = np.asarray(cells, np.int64)[np.asarray(node_idx, np.int64)]
    return float(
        sum(segment_cost(pts[i], pts[i + 1], cost_per_m, cell_m) for i in range(len(pts) - 1))
    )
