"""Path planning (paper section IV.B): navigation grid, A*, simplification, the plan stage."""

from scenebot._lazy import lazy_getattr
from scenebot.plan.config import PlanConfig

_LAZY = ("scenebot.plan.navgrid", "scenebot.plan.path")

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


__getattr__ = lazy_getattr(__name__, _LAZY)
