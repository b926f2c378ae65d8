"""A*, path simplification and plan_path: optimality and property tests."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from scenebot.plan import PlanConfig, PlanFailure, PlanFailureReason, PlannedPath, plan_path
from scenebot.plan.astar import astar, effective_cost, path_cost
from scenebot.plan.navgrid import GridGeometry, NavGrid, grid_from_counts
from scenebot.plan.path import GridPlanner
from scenebot.plan.simplify import merge_runs, polyline_cost, simplify_path

SIMPLIFY = PlanConfig().simplify_factor


def _dijkstra_cost(cost: np.ndarray, s, t, cell=1.0) -> float:
    """Reference: scipy Dijkstra on the explicit 8-neighbour graph (entering-cell costs)."""
    ny, nx = cost.shape
    rows, cols, w = [], [], []
    for y in range(ny):
        for x in range(nx):
            for dy in (-1, 0, 1):
                for dx in (-1, 0, 1):
                    if (dy or dx) and 0 <= y + dy < ny and 0 <= x + dx < nx:
                        rows.append(y * nx + x)
                        cols.append((y + dy) * nx + x + dx)
                        w.append(cell * math.hypot(dy, dx) * cost[y + dy, x + dx])
    g = csr_matrix((w, (rows, cols)), shape=(ny * nx, ny * nx))
    return float(dijkstra(g, indices=s[0] * nx + s[1])[t[0] * nx + t[1]])


def _grid_strategy(max_side=14):
    return st.tuples(
        st.integers(4, max_side),
        st.integers(4, max_side),
        st.integers(0, 2**31 - 1),
        st.floats(0.0, 0.45),
    )


def _random_grid(ny, nx, seed, p_lethal):
    rng = np.random.default_rng(seed)
    cost = 1.0 + rng.exponential(1.0, (ny, nx))
    lethal = rng.random((ny, nx)) < p_lethal
    free = np.argwhere(~lethal)
    if len(free) < 2:
        lethal[:] = False
        free = np.argwhere(~lethal)
    i, j = rng.choice(len(free), 2, replace=False)
    return cost, lethal, tuple(free[i]), tuple(free[j])


@settings(max_examples=40, deadline=None)
@given(_grid_strategy(10))
def test_astar_is_optimal_against_dijkstra(params):
    ny, nx, seed, _ = params
    cost, _, s, t = _random_grid(ny, nx, seed, 0.0)
    res = astar(cost, np.zeros_like(cost, bool), s, t, cell_m=0.05)
    assert res.cost == pytest.approx(_dijkstra_cost(cost, s, t, 0.05), rel=1e-9)
    assert res.cost == pytest.approx(path_cost(res.cells, cost, 0.05), rel=1e-9)
    assert tuple(res.cells[0]) == s and tuple(res.cells[-1]) == t
    assert np.abs(np.diff(res.cells, axis=0)).max() <= 1


@settings(max_examples=60, deadline=None)
@given(_grid_strategy())
def test_path_avoids_lethal_cells_whenever_a_route_around_exists(params):
    ny, nx, seed, p = params
    cost, lethal, s, t = _random_grid(ny, nx, seed, p)
    res = astar(cost, lethal, s, t)
    labels, _ = ndimage.label(~lethal, structure=np.ones((3, 3)))
    connected = labels[s] == labels[t]
    entered = lethal[res.cells[1:, 0], res.cells[1:, 1]].any()
    assert res.found
    if connected:
        assert not entered
        # and optimal among lethal-free paths
        blocked = np.where(lethal, 1e12, cost)
        assert res.cost == pytest.approx(_dijkstra_cost(blocked, s, t), rel=1e-9)
    else:
        assert entered


@settings(max_examples=60, deadline=None)
@given(_grid_strategy(), st.floats(1.0, 2.0))
def test_simplification_bound_and_endpoints(params, factor):
    ny, nx, seed, p = params
    cost, lethal, s, t = _random_grid(ny, nx, seed, p)
    eff = effective_cost(cost, lethal)
    res = astar(cost, lethal, s, t, cell_m=0.1)
    keep = simplify_path(res.cells, eff, 0.1, factor)
    assert keep[0] == 0 and keep[-1] == len(res.cells) - 1
    assert np.all(np.diff(keep) > 0)
    assert set(keep.tolist()) <= set(merge_runs(res.cells).tolist())
    simplified = polyline_cost(res.cells, keep, eff, 0.1)
    assert simplified <= factor * res.cost * (1 + 1e-9)
    # merging same-angle runs alone does not change the cost
    merged = polyline_cost(res.cells, merge_runs(res.cells), eff, 0.1)
    assert merged == pytest.approx(res.cost, rel=1e-9)


def test_simplify_straightens_a_staircase_in_free_space():
    cost = np.ones((30, 30))
    cells = np.array([[0, 0]] + [[i // 2 + i % 2, i // 2] for i in range(1, 40)])
    cells = np.array([[y, x] for y, x in cells])
    keep = simplify_path(cells, cost, 1.0, 1.1)
    assert len(keep) == 2  # the straight line costs less than the staircase


def _room_grid(n=60):
    """A 6 m square room with a wall across the middle that has a door near one end."""
    geo = GridGeometry((0.0, 0.0), 6.0 / n, (n, n))
    counts = np.zeros((n, n), np.int32)
    counts[[0, -1], :] = 20
    counts[:, [0, -1]] = 20
    counts[n // 2, : int(0.8 * n)] = 20  # wall, door on the right
    return grid_from_counts(counts, geo, PlanConfig(kde_sigma_m=0.1, inflate_m=0.1))


def test_plan_path_routes_through_the_door_and_keeps_exact_endpoints():
    g = _room_grid()
    start, goal = np.array([1.0, 1.2]), np.array([1.0, 4.8])
    res = plan_path(g, start, goal, SIMPLIFY)
    assert isinstance(res, PlannedPath)
    np.testing.assert_array_equal(res.waypoints_xy[0], start)
    np.testing.assert_array_equal(res.waypoints_xy[-1], goal)
    assert res.waypoints_xy[:, 0].max() > 0.8 * 6.0  # went around through the door
    assert len(res.waypoints_xy) < 10
    assert res.cost <= SIMPLIFY * res.astar_cost * (1 + 1e-9)
    # the straight segments stay out of lethal cells
    for a, b in zip(res.waypoints_xy[:-1], res.waypoints_xy[1:], strict=True):
        for u in np.linspace(0, 1, 200):
            c = g.geometry.cell_of(a + u * (b - a))
            assert not g.lethal[c[0], c[1]]


def test_plan_path_failures_have_reasons():
    g = _room_grid()
    out = plan_path(g, np.array([1.0, 1.0]), np.array([9.0, 1.0]), SIMPLIFY)
    assert isinstance(out, PlanFailure) and out.reason is PlanFailureReason.GOAL_OUTSIDE_GRID
    out = plan_path(g, np.array([1.0, 1.0]), np.array([1.0, 3.0]), SIMPLIFY)  # on the wall
    assert isinstance(out, PlanFailure) and out.reason is PlanFailureReason.GOAL_IN_OBSTACLE
    closed = NavGrid(g.geometry, g.counts, g.kde, g.score, g.lethal.copy(), g.cost_per_m)
    closed.lethal[27:34, :] = True  # close the door
    out = plan_path(closed, np.array([1.0, 1.0]), np.array([1.0, 4.8]), SIMPLIFY)
    assert isinstance(out, PlanFailure) and out.reason is PlanFailureReason.NO_ROUTE
    assert "crosses an obstacle" in out.message


def test_grid_planner_learns_a_bumped_obstacle():
    g = _room_grid()
    planner = GridPlanner(g, SIMPLIFY)
    before = planner(np.array([1.0, 1.0]), np.array([5.0, 1.0]))
    assert isinstance(before, PlannedPath)
    assert planner.mark_obstacle(np.array([3.0, 1.0]), 0.4) > 0
    after = planner(np.array([1.0, 1.0]), np.array([5.0, 1.0]))
    assert isinstance(after, PlannedPath)
    assert after.astar_cost > before.astar_cost
    assert not g.lethal[g.geometry.cell_of(np.array([3.0, 1.0]))[0], 30]  # original untouched
