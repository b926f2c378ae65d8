"""Reference cameras of bring-your-own photos (``evaluate.reference_cameras``), for evaluation.

A person's photos carry no true poses; a calibrated set (a gantry, a motion-capture rig, a
simulated capture given as a folder) comes with its cameras in a file. This module reads the
three formats users have and writes them as capture-log photo records (``log.jsonl``: ``image``
and ``truth`` with ``center`` and ``R_cam_from_world``), so the evaluation reads them exactly
as it reads a simulated robot's log. Read by the evaluation only, never by a decision.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from scenebot.capturelog import read_log


class ReferenceError(ValueError):
    """The reference cameras cannot be read; the message names the file and the fix."""


def _read_par(path: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Middlebury ``*_par.txt``: the count, then ``name K(9) R(9) t(3)`` per photo."""
    lines = [ln.split() for ln in path.read_text(encoding="utf-8").splitlines() if ln.strip()]
    if lines and len(lines[0]) == 1:
        lines = lines[1:]  # the photo count
    out = {}
    for k, parts in enumerate(lines, start=2):
        if len(parts) != 22:
            raise ReferenceError(
                f"{path}:{k}: expected `name k11 .. k33 r11 .. r33 t1 t2 t3` (22 fields), got "
                f"{len(parts)}"
            )
        R = np.asarray(parts[10:19], np.float64).reshape(3, 3)
        t = np.asarray(parts[19:22], np.float64)
        out[Path(parts[0]).name] = (R, -R.T @ t)
    return out


def _read_colmap(path: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    import pycolmap

    rec = pycolmap.Reconstruction(str(path))
    out = {}
    for iid in rec.reg_image_ids():
        im = rec.image(iid)
        R = np.asarray(im.cam_from_world().rotation.matrix(), np.float64)
        out[Path(im.name).name] = (R, np.asarray(im.projection_center(), np.float64))
    return out


def _read_log(path: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    out = {}
    for rec in read_log(path):
        tr = rec.get("truth") or {}
        if rec.get("type") == "photo" and tr.get("R_cam_from_world") is not None:
            out[Path(rec["image"]).name] = (
                np.asarray(tr["R_cam_from_world"], np.float64),
                np.asarray(tr["center"], np.float64),
            )
    return out


def read_reference_cameras(path: str | Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Photo file name -> (R_cam_from_world (3, 3), camera centre (3,)).

    Raises:
        ReferenceError: missing file, unknown format, or no camera in it.
    """
    path = Path(path)
    if not path.exists():
        raise ReferenceError(
            f"evaluate.reference_cameras: {path} not found (a Middlebury *_par.txt, a COLMAP "
            "model folder or a capture log.jsonl)"
        )
    if path.is_dir():
        if not any((path / f"images.{x}").is_file() for x in ("bin", "txt")):
            raise ReferenceError(f"evaluate.reference_cameras: {path} holds no COLMAP model")
        cams = _read_colmap(path)
    elif path.suffix == ".jsonl":
        cams = _read_log(path)
    else:
        cams = _read_par(path)
    if not cams:
        raise ReferenceError(f"evaluate.reference_cameras: {path} holds no camera pose")
    return cams


def write_reference_log(cams: dict[str, tuple[np.ndarray, np.ndarray]], out: str | Path) -> int:
    """Write the cameras as capture-log photo records (``image``, ``truth``); returns the
    count. The records say where they came from (``source: reference``)."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with out.open("w", encoding="utf-8") as fh:
        for k, (name, (R, c)) in enumerate(sorted(cams.items())):
            rec = {
                "type": "photo",
                "index": k,
                "image": name,
                "source": "reference",
                "truth": {"center": c.tolist(), "R_cam_from_world": R.tolist()},
            }
            fh.write(json.dumps(rec) + "\n")
    return len(cams)
