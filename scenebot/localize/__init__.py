"""Visual localization (paper section IV.B): SIFT, FLANN KD-tree matching, DLT/P3P pose."""

from scenebot.localize.config import LocalizeConfig

_LAZY = ("scenebot.localize.index", "scenebot.localize.localize")

__all__ = [
    "DescriptorIndex",
    "FailureReason",
    "LocalizationFailure",
    "LocalizationMap",
    "LocalizeConfig",
    "MapDescriptors",
    "PoseEstimate",
    "localize",
    "make_localizer",
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
