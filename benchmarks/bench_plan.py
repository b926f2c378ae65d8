"""Planning speed: navigation grid (KDE), A*, simplification on 100x100 and 1000x1000 grids.

The scene is an office-like room (6 x 5 m walls, desks, a cabinet, boxes) as sparse points;
the path crosses the room around the furniture. Reference (same run, same grid): scipy's
compiled Dijkstra (``scipy.sparse.csgraph.dijkstra``) on the explicit 8-neighbour graph with
the same step costs, from the start cell, graph construction not counted.

    .venv/bin/python benchmarks/bench_plan.py [--repeats 7]

Prints medians of the repeats (ms) and ratios; the issue's budgets are 5 ms (100 cells) and
0.5 s (1000 cells) for KDE + A* + simplification.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from scenebot.plan import PlanConfig, build_navgrid
from scenebot.plan.astar import astar, effective_cost
from scenebot.plan.simplify import simplify_path

BUDGET_S = {100: 0.005, 1000: 0.5}


def office_points(rng: np.random.Generator) -> np.ndarray:
    """(N, 3) points on walls and furniture of a 6 x 5 m room, z in -0.3..2.2 m."""
    pts = []

    def wall(a, b, k, z0=-0.3, z1=2.2):
        a, b = np.asarray(a, float), np.asarray(b, float)
        t = rng.random(k)[:, None]
        p = a + (b - a) * t + rng.normal(0, 0.01, (k, 2))
        return np.c_[p, rng.uniform(z0, z1, k)]

    corners = [(0, 0), (6, 0), (6, 5), (0, 5)]
    for i in range(4):
        pts.append(wall(corners[i], corners[(i + 1) % 4], 8000))
    for x0, y0, x1, y1, z1 in [
        (1.0, 0.0, 2.6, 0.8, 0.45),  # desk
        (3.2, 2.0, 4.0, 3.6, 0.45),  # desk in the middle
        (5.4, 1.0, 6.0, 2.8, 1.8),  # cabinet
        (1.5, 3.0, 2.0, 3.5, 0.3),  # box
        (0.0, 4.2, 1.2, 5.0, 0.45),  # desk
    ]:
        c = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
        for i in range(4):
            pts.append(wall(c[i], c[(i + 1) % 4], 1500, -0.3, z1))
    pts.append(np.c_[rng.uniform(0, 6, (3000, 2)), rng.uniform(-0.36, -0.34, 3000)])  # floor
    return np.vstack(pts)


def reference_dijkstra_s(cost: np.ndarray, start: tuple[int, int], cell: float) -> float:
    ny, nx = cost.shape
    idx = np.arange(ny * nx).reshape(ny, nx)
    rows, cols, w = [], [], []
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if not (dy or dx):
                continue
            src = idx[max(0, -dy) : ny - max(0, dy), max(0, -dx) : nx - max(0, dx)]
            dst = idx[max(0, dy) : ny + min(0, dy), max(0, dx) : nx + min(0, dx)]
            rows.append(src.ravel())
            cols.append(dst.ravel())
            w.append(cell * math.hypot(dy, dx) * cost.ravel()[dst.ravel()])
    g = csr_matrix((np.concatenate(w), (np.concatenate(rows), np.concatenate(cols))))
    t0 = time.perf_counter()
    dijkstra(g, indices=start[0] * nx + start[1])
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    pts = office_points(rng)
    cams = np.array([[0.4, 0.4], [5.6, 4.6]])  # explored area: the whole room
    start, goal = np.array([0.5, 1.5]), np.array([4.8, 0.5])
    print(f"points: {len(pts)}; path {start.tolist()} -> {goal.tolist()} m")
    print(
        f"{'cells':>6} {'grid':>9} {'kde ms':>8} {'A* ms':>8} {'simpl ms':>8} {'total ms':>9}"
        f" {'budget ms':>9} {'tot/budg':>8} {'dijkstra ms':>11} {'A*/dijk':>8} {'expanded':>9}"
        f" {'nodes':>6}"
    )
    for n in (100, 1000):
        cfg = PlanConfig(n_cells=n, margin_m=0.4)
        t_kde, t_astar, t_simp = [], [], []
        for _ in range(args.repeats if n == 100 else max(3, args.repeats // 2)):
            t0 = time.perf_counter()
            grid = build_navgrid(pts, cams, cfg)
            t1 = time.perf_counter()
            g = grid.geometry
            s, t = tuple(g.cell_of(start)), tuple(g.cell_of(goal))
            res = astar(grid.cost_per_m, grid.lethal, s, t, g.cell_m)
            t2 = time.perf_counter()
            keep = simplify_path(res.cells, effective_cost(grid.cost_per_m, grid.lethal), g.cell_m)
            t3 = time.perf_counter()
            t_kde.append(t1 - t0)
            t_astar.append(t2 - t1)
            t_simp.append(t3 - t2)
        med = [float(np.median(v)) * 1e3 for v in (t_kde, t_astar, t_simp)]
        total = sum(med)
        ref = (
            float(
                np.median(
                    [
                        reference_dijkstra_s(
                            effective_cost(grid.cost_per_m, grid.lethal), s, g.cell_m
                        )
                        for _ in range(3)
                    ]
                )
            )
            * 1e3
        )
        print(
            f"{n:>6} {g.shape[1]}x{g.shape[0]:<5} {med[0]:8.2f} {med[1]:8.2f} {med[2]:8.2f}"
            f" {total:9.2f} {BUDGET_S[n] * 1e3:9.1f} {total / (BUDGET_S[n] * 1e3):8.2f}"
            f" {ref:11.2f} {med[1] / ref:8.2f} {res.expanded:>9} {len(keep):>6}"
        )


if __name__ == "__main__":
    main()
