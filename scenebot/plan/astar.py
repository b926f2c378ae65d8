"""8-neighbour A* on a cost grid (paper section IV.B).

Moving from a cell into one of its 8 neighbours costs the length of the move (m) times the
travel cost per metre of the cell entered. Lethal cells are not forbidden outright: they cost
a penalty per metre larger than any path through non-lethal cells can cost, so the search
never enters a lethal cell when a route around exists, yet still returns *a* path (which the
caller reports as blocked) when the start is boxed in or the goal sits in an obstacle.

The search is written for CPython speed: a padded flat grid (the one-cell border costs
infinity, so no bounds checks), plain lists, ``heapq`` keyed by ``(f, -g)`` so that ties go to
the node nearest the goal, and the octile-distance heuristic scaled by the smallest cost per
metre (admissible, so the path is optimal).
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class AStarResult:
    """The outcome of one search.

    Attributes:
        cells: (K, 2) int64 ``[iy, ix]`` cells from start to goal (both included); empty when
            no path exists.
        cost: total path cost (m times cost per metre, penalties included); inf if none.
        expanded: number of cells expanded by the search.
        lethal_entered: number of lethal cells on the path after the start cell.
    """

    cells: np.ndarray
    cost: float
    expanded: int
    lethal_entered: int

    @property
    def found(self) -> bool:
        return len(self.cells) > 0


def lethal_penalty_per_m(cost_per_m: np.ndarray, lethal: np.ndarray) -> float:
    """A cost per metre for lethal cells that exceeds every lethal-free path's total cost.

    A lethal-free path visits each cell at most once with moves of at most sqrt(2) cells, so
    its cost is below ``n_cells * sqrt(2) * cell * max_cost``; one lethal move of at least one
    cell length at the returned rate costs more than that (for any cell length).
    """
    free = cost_per_m[~lethal]
    cmax = float(free.max()) if free.size else 1.0
    return 4.0 * cost_per_m.size * cmax + 1.0


def effective_cost(cost_per_m: np.ndarray, lethal: np.ndarray) -> np.ndarray:
    """Cost per metre used by the search: ``cost_per_m`` with lethal cells at the penalty.

    Returns:
        (ny, nx) float64.
    """
    return np.where(lethal, lethal_penalty_per_m(cost_per_m, lethal), cost_per_m).astype(float)


def astar(
    cost_per_m: np.ndarray,
    lethal: np.ndarray,
    start: tuple[int, int],
    goal: tuple[int, int],
    cell_m: float = 1.0,
) -> AStarResult:
    """Cheapest 8-connected path from ``start`` to ``goal``.

    Args:
        cost_per_m: (ny, nx) travel cost per metre of each cell, all >= some positive minimum.
        lethal: (ny, nx) bool obstacle cells (entered only when there is no route around).
        start: ``(iy, ix)`` start cell (inside the grid).
        goal: ``(iy, ix)`` goal cell (inside the grid).
        cell_m: cell edge length (m); scales the costs only.

    Returns:
        The path, its cost, the number of expanded cells and how many lethal cells it enters.

    Raises:
        ValueError: start or goal outside the grid, or a non-positive cost.
    """
    cost_per_m = np.asarray(cost_per_m, float)
    lethal = np.asarray(lethal, bool)
    ny, nx = cost_per_m.shape
    for name, (y, x) in (("start", start), ("goal", goal)):
        if not (0 <= y < ny and 0 <= x < nx):
            raise ValueError(f"astar: {name} cell {(y, x)} is outside the {ny}x{nx} grid")
    eff = effective_cost(cost_per_m, lethal)
    cmin = float(eff.min())
    if not cmin > 0.0:
        raise ValueError("astar: every cell cost per metre must be positive")
    w = nx + 2
    padded = np.full((ny + 2, w), math.inf)
    padded[1:-1, 1:-1] = eff
    pc = padded.ravel().tolist()
    n = len(pc)
    s = (start[0] + 1) * w + start[1] + 1
    t = (goal[0] + 1) * w + goal[1] + 1
    ty, tx = divmod(t, w)
    straight = cell_m
    diag = cell_m * math.sqrt(2.0)
    # Octile distance (m) to the goal times the cheapest cost per metre: admissible.
    yy = np.abs(np.arange(ny + 2) - ty)[:, None].astype(float)
    xx = np.abs(np.arange(w) - tx)[None, :].astype(float)
    heur = (straight * (xx + yy) + (diag - 2.0 * straight) * np.minimum(xx, yy)) * cmin
    hl = heur.ravel().tolist()
    moves = (
        (1, straight),
        (-1, straight),
        (w, straight),
        (-w, straight),
        (w + 1, diag),
        (w - 1, diag),
        (-w + 1, diag),
        (-w - 1, diag),
    )
    g = [math.inf] * n
    parent = [-1] * n
    closed = bytearray(n)
    g[s] = 0.0
    heap: list[tuple[float, float, int]] = [(0.0, -0.0, s)]
    push, pop = heapq.heappush, heapq.heappop
    expanded = 0
    found = False
    while heap:
        _, neg_g, u = pop(heap)
        if closed[u]:
            continue
        if u == t:
            found = True
            break
        closed[u] = 1
        expanded += 1
        gu = -neg_g
        for d, length in moves:
            v = u + d
            if closed[v]:
                continue
            ng = gu + length * pc[v]
            if ng < g[v]:
                g[v] = ng
                parent[v] = u
                push(heap, (ng + hl[v], -ng, v))
    if not found:
        return AStarResult(np.zeros((0, 2), np.int64), math.inf, expanded, 0)
    path = [t]
    while path[-1] != s:
        path.append(parent[path[-1]])
    path.reverse()
    flat = np.array(path, np.int64)
    cells = np.stack([flat // w - 1, flat % w - 1], axis=1)
    n_lethal = int(lethal[cells[1:, 0], cells[1:, 1]].sum()) if len(cells) > 1 else 0
    return AStarResult(cells, float(g[t]), expanded, n_lethal)


def path_cost(cells: np.ndarray, cost_per_m: np.ndarray, cell_m: float = 1.0) -> float:
    """Cost of an 8-connected cell path under the A* step costs (no penalties added).

    Args:
        cells: (K, 2) ``[iy, ix]`` consecutive 8-neighbours.
        cost_per_m: (ny, nx) cost per metre (pass :func:`effective_cost` to include penalties).
        cell_m: cell edge length (m).
    """
    cells = np.asarray(cells, np.int64)
    if len(cells) < 2:
        return 0.0
    step = np.diff(cells, axis=0)
    if np.abs(step).max() > 1:
        raise ValueError("path_cost: consecutive cells must be 8-neighbours")
    length = np.where(np.abs(step).sum(axis=1) == 2, math.sqrt(2.0), 1.0) * cell_m
    return float((length * cost_per_m[cells[1:, 0], cells[1:, 1]]).sum())
