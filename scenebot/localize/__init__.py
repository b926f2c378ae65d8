"""Visual localization (paper section IV.B): SIFT, FLANN KD-tree matching, DLT/P3P pose."""

from scenebot.localize.config import LocalizeConfig
from scenebot.localize.index import DescriptorIndex, MapDescriptors
from scenebot.localize.localize import (
    FailureReason,
    LocalizationFailure,
    LocalizationMap,
    PoseEstimate,
    localize,
    make_localizer,
)

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
