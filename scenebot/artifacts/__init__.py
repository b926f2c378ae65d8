"""The files one stage writes and a later stage reads (DESIGN.md, the artifact contract), with
their one reader and writer: ``mesh.ply`` (:mod:`~scenebot.artifacts.mesh`), ``freespace.npz``
(:mod:`~scenebot.artifacts.freespace`), ``candidates.csv`` (:mod:`~scenebot.artifacts.candidates`),
``goals_preview.npz`` (:mod:`~scenebot.artifacts.previews`), and where a round's photos and
pages lie (:func:`round_dir`, :func:`inbox_dir`).
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


def round_dir(scene_dir: str | Path, r: int) -> Path:
    """``<scene_dir>/round_XXX``: round ``r``'s folder."""
    return Path(scene_dir) / f"round_{int(r):03d}"


def round_index(path: str | Path) -> int | None:
    """The round number of ``round_XXX`` in ``path`` (the last one), None without one."""
    found = re.findall(r"round_(\d+)", str(path))
    return int(found[-1]) if found else None


def inbox_dir(scene_dir: str | Path, guide_round: int) -> Path:
    """Where a person puts the photos taken following round ``guide_round``'s guide
    (``round_XXX/guide/index.html``): the next round's ``capture/inbox/`` (the photos of a
    round are that round's capture, as a robot's; registered by the next run, never
    modified)."""
    return round_dir(scene_dir, guide_round + 1) / "capture" / "inbox"
