"""Visual localization (paper section IV.B): SIFT, FLANN KD-tree matching, DLT/P3P pose."""

from scenebot._lazy import lazy_getattr
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


__getattr__ = lazy_getattr(__name__, _LAZY)
