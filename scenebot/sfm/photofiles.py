"""Which files of a folder are photos, and their order: one definition for the workflow
(the sfm rule's inputs in ``rules/common.smk``) and the sfm stage's reader
(:func:`scenebot.sfm.photos.photos_from_folder`).

A photo is a regular file (or a link to one) directly in the folder whose suffix is
``.jpg``, ``.jpeg`` or ``.png`` in any case (``0007.Jpg``) and whose name does not start
with a dot (hidden files such as macOS ``._0007.jpg`` metadata are not photos). Photos are in
natural order of their names: case-insensitive, runs of digits by value (``img2`` before
``img10``), the exact name breaking ties.

Standard library only: the Snakefile imports this at every start.
"""

from __future__ import annotations

import hashlib
import re
from pathlib import Path

PHOTO_SUFFIXES = (".jpg", ".jpeg", ".png")
"""Suffixes of photo files, lower case (a file's suffix is compared in lower case)."""

_DIGITS = re.compile(r"(\d+)")


def is_photo_name(name: str) -> bool:
    """Whether a file called ``name`` is a photo by its name (see the module docstring)."""
    return not name.startswith(".") and Path(name).suffix.lower() in PHOTO_SUFFIXES


def photo_order(name: str) -> tuple:
    """Sort key of photo names: natural, case-insensitive order; the exact name breaks ties."""
    parts = _DIGITS.split(name.casefold())
    key = tuple((0, int(p), "") if _DIGITS.fullmatch(p) else (1, 0, p) for p in parts if p)
    return key, name


def photo_files(folder: Path | str) -> list[Path]:
    """The photo files of ``folder`` (not recursive), in :func:`photo_order`; ``[]`` when
    the folder does not exist (the sfm stage says so by name)."""
    folder = Path(folder)
    if not folder.is_dir():
        return []
    files = [p for p in folder.iterdir() if is_photo_name(p.name) and p.is_file()]
    return sorted(files, key=lambda p: photo_order(p.name))


def other_files(folder: Path | str) -> list[Path]:
    """The files of ``folder`` that are not photos (ignored; the reader names them)."""
    folder = Path(folder)
    if not folder.is_dir():
        return []
    return sorted(p for p in folder.iterdir() if p.is_file() and not is_photo_name(p.name))


def sha256_of(path: Path) -> str:
    """The SHA-256 of a file's bytes (hex): the same photo under another name is a repeat."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()
