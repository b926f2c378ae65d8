"""scenebot: autonomous scene capture with a mobile robot.

A robot explores an unknown room, builds a map from its photos, and chooses every next photo
by the predicted quality of an image synthesized there (unstructured lumigraph heuristic).
"""

import os

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")  # never reach the network at run time

__version__ = "0.1.0"
