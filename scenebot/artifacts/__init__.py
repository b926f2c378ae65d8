"""The files one stage writes and a later stage reads (DESIGN.md, the artifact contract), with
their one reader and writer: ``mesh.ply`` (:mod:`~scenebot.artifacts.mesh`), ``freespace.npz``
(:mod:`~scenebot.artifacts.freespace`), ``candidates.csv`` (:mod:`~scenebot.artifacts.candidates`).
Stages import these, never each other's internals.
"""

from __future__ import annotations

import re
from pathlib import Path


def round_name(*paths: str | Path) -> str:
    """``round_XXX`` found in the paths, else the first path (for messages)."""
    for p in paths:
        m = re.search(r"round_\d+", str(p))
        if m:
            return m.group(0)
    return str(paths[0]) if paths else "?"
