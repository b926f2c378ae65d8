"""Plan one path on a navigation grid: A*, then simplification, with typed failures."""

from __future__ import annotations

import enum
import logging
from dataclasses import dataclass, field

import numpy as np

from scenebot.plan.astar import astar, effective_cost
from scenebot.plan.navgrid import NavGrid
from scenebot.plan.simplify import polyline_cost, simplify_path

log = logging.getLogger(__name__)


class PlanFailureReason(enum.StrEnum):
    """Why no path was planned."""

    START_OUTSIDE_GRID = "start_outside_grid"
    GOAL_OUTSIDE_GRID = "goal_outside_grid"
    GOAL_IN_OBSTACLE = "goal_in_obstacle"
    NO_ROUTE = "no_route_around_obstacles"


@dataclass(frozen=True)
class PlanFailure:
    """A goal that cannot be planned to, and why (for the log and paths.json)."""

    reason: PlanFailureReason
    message: str

    def as_dict(self) -> dict:
        return {"status": "skipped", "reason": str(self.reason), "message": self.message}


@dataclass(frozen=True)
class PlannedPath:
    """A simplified path.

    Attributes:
        waypoints_xy: (M, 2) map-frame nodes (m): the exact start, intermediate cell centres,
            the exact goal.
        cells: (M, 2) ``[iy, ix]`` grid cells of the nodes.
        astar_cost: cost of the A* path (m times cost per metre).
        cost: cost of the simplified path (<= simplify_factor * astar_cost).
        astar_cells: number of cells on the A* path.
        expanded: cells expanded by A*.
        start_in_obstacle: the start cell was lethal (the path leaves it by the cheapest way).
    """

    waypoints_xy: np.ndarray
    cells: np.ndarray
    astar_cost: float
    cost: float
    astar_cells: int
    expanded: int
    start_in_obstacle: bool = False
    extra: dict = field(default_factory=dict)

    @property
    def length_m(self) -> float:
        return float(np.linalg.norm(np.diff(self.waypoints_xy, axis=0), axis=1).sum())

    def as_dict(self) -> dict:
        return {
            "status": "ok",
            "waypoints": [[float(x), float(y)] for x, y in self.waypoints_xy],
            "cells": [[int(a), int(b)] for a, b in self.cells],
            "length_m": self.length_m,
            "astar_cost": self.astar_cost,
            "cost": self.cost,
            "astar_cells": self.astar_cells,
            "expanded": self.expanded,
            "start_in_obstacle": self.start_in_obstacle,
        }


def plan_path(
    grid: NavGrid, start_xy: np.ndarray, goal_xy: np.ndarray, simplify_factor: float
) -> PlannedPath | PlanFailure:
    """A* from ``start_xy`` to ``goal_xy`` on ``grid``, then path simplification.

    Args:
        grid: the navigation grid.
        start_xy: (2,) robot position (m, map frame).
        goal_xy: (2,) goal position (m, map frame).
        simplify_factor: ``plan.simplify_factor``; see
            :func:`scenebot.plan.simplify.simplify_path`.

    Returns:
        The path, or a :class:`PlanFailure` when the start or goal is outside the grid, the
        goal cell is an obstacle, or every route crosses an obstacle.
    """
    geo = grid.geometry
    start_xy = np.asarray(start_xy, float)
    goal_xy = np.asarray(goal_xy, float)
    sc = geo.cell_of(start_xy)
    gc = geo.cell_of(goal_xy)
    if not geo.contains_cell(sc):
        return PlanFailure(
            PlanFailureReason.START_OUTSIDE_GRID,
            f"start {start_xy.round(3).tolist()} m lies outside the navigation grid",
        )
    if not geo.contains_cell(gc):
        return PlanFailure(
            PlanFailureReason.GOAL_OUTSIDE_GRID,
            f"goal {goal_xy.round(3).tolist()} m lies outside the navigation grid "
            f"(origin {list(geo.origin_xy)}, {geo.shape[1]}x{geo.shape[0]} cells of "
            f"{geo.cell_m:.3f} m; raise plan.margin_m to cover it)",
        )
    if grid.lethal[gc[0], gc[1]]:
        return PlanFailure(
            PlanFailureReason.GOAL_IN_OBSTACLE,
            f"goal {goal_xy.round(3).tolist()} m lies in an obstacle cell "
            f"(obstacle score {grid.score[gc[0], gc[1]]:.2f} points)",
        )
    eff = effective_cost(grid.cost_per_m, grid.lethal)
    res = astar(grid.cost_per_m, grid.lethal, tuple(sc), tuple(gc), geo.cell_m)
    if not res.found:
        return _blocked(res, goal_xy)
    # Leaving an obstacle blob around the start is allowed; entering any obstacle is not.
    start_lethal = bool(grid.lethal[sc[0], sc[1]])
    inside = grid.lethal[res.cells[:, 0], res.cells[:, 1]]
    first_free = int(np.argmin(inside)) if start_lethal else 1
    if inside[first_free:].any():
        return _blocked(res, goal_xy)
    keep = simplify_path(res.cells, eff, geo.cell_m, simplify_factor)
    cells = res.cells[keep]
    xy = geo.centre_of(cells)
    xy[0] = start_xy
    xy[-1] = goal_xy
    return PlannedPath(
        waypoints_xy=xy,
        cells=cells,
        astar_cost=res.cost,
        cost=polyline_cost(res.cells, keep, eff, geo.cell_m),
        astar_cells=len(res.cells),
        expanded=res.expanded,
        start_in_obstacle=start_lethal,
    )


def _blocked(res, goal_xy: np.ndarray) -> PlanFailure:
    return PlanFailure(
        PlanFailureReason.NO_ROUTE,
        f"every route to goal {goal_xy.round(3).tolist()} m crosses an obstacle "
        f"(A* expanded {res.expanded} cells)",
    )


class GridPlanner:
    """Plans on a navigation grid and learns obstacles found by the bumper while following.

    Bump marks are local guesses (a disk around the contact point). When they wall the robot
    in, so that no route leaves the spot it stands on, but the map alone has one, the marks
    are forgotten and that route is returned (``forgotten_marks`` counts it): the robot meets
    a real obstacle again, and gives up on the goal after ``follow.max_obstacles`` bumps.

    Args:
        grid: the navigation grid (copied; the original is not changed).
        simplify_factor: ``plan.simplify_factor``; see
            :func:`scenebot.plan.simplify.simplify_path`.
    """

    def __init__(self, grid: NavGrid, simplify_factor: float):
        self.grid = NavGrid(
            grid.geometry,
            grid.counts.copy(),
            grid.kde.copy(),
            grid.score.copy(),
            grid.lethal.copy(),
            grid.cost_per_m.copy(),
        )
        self.simplify_factor = simplify_factor
        self._map_lethal = grid.lethal.copy()  # the map's obstacles, without bump marks
        self.forgotten_marks = 0

    def __call__(self, start_xy: np.ndarray, goal_xy: np.ndarray) -> PlannedPath | PlanFailure:
        res = plan_path(self.grid, start_xy, goal_xy, self.simplify_factor)
        if (
            isinstance(res, PlanFailure)
            and res.reason is PlanFailureReason.NO_ROUTE
            and not np.array_equal(self.grid.lethal, self._map_lethal)  # bump marks exist
        ):
            g = self.grid
            plain = NavGrid(g.geometry, g.counts, g.kde, g.score, self._map_lethal, g.cost_per_m)
            alt = plan_path(plain, start_xy, goal_xy, self.simplify_factor)
            if isinstance(alt, PlannedPath):
                self.grid.lethal = self._map_lethal.copy()
                self.forgotten_marks += 1
                log.info("bump marks wall the robot in: forgotten, planning on the map alone")
                return alt
        return res

    def mark_obstacle(self, xy: np.ndarray, radius_m: float) -> int:
        """Make the cells within ``radius_m`` of ``xy`` (m) lethal; returns how many changed."""
        g = self.grid.geometry
        ny, nx = g.shape
        centres = g.centre_of(np.stack(np.mgrid[0:ny, 0:nx], axis=-1))
        near = np.hypot(centres[..., 0] - xy[0], centres[..., 1] - xy[1]) <= max(
            radius_m, 0.5 * g.cell_m
        )
        changed = int((near & ~self.grid.lethal).sum())
        self.grid.lethal |= near
        return changed
