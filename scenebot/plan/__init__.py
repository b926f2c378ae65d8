"""Path planning (paper section IV.B): navigation grid, A*, simplification, the plan stage."""

from scenebot.plan.config import PlanConfig
from scenebot.plan.navgrid import GridGeometry, NavGrid, build_navgrid
from scenebot.plan.path import PlanFailure, PlanFailureReason, PlannedPath, plan_path

__all__ = [
    "GridGeometry",
    "NavGrid",
    "PlanConfig",
    "PlanFailure",
    "PlanFailureReason",
    "PlannedPath",
    "build_navgrid",
    "plan_path",
]
