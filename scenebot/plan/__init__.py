"""Path planning (paper section IV.B): navigation grid, A*, simplification, the plan stage."""

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


def __getattr__(name: str):
    """Import the heavy modules (OpenCV, pycolmap, scipy) only when used: the workflow loads
    this package's config at every start."""
    import importlib

    for module in _LAZY:
        mod = importlib.import_module(module)
        if hasattr(mod, name):
            return getattr(mod, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
