"""Visual localization (paper section IV.B): SIFT, FLANN KD-tree matching, DLT/P3P pose.

The algorithms (OpenCV, pycolmap, scipy) load on first use: the workflow imports this
package's config at every start.
"""

from scenebot._lazy import lazy_getattr
from scenebot.localize.config import LocalizeConfig

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

__getattr__ = lazy_getattr(__name__, ("scenebot.localize.index", "scenebot.localize.locate"))
