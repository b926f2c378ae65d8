"""The taichi PatchMatch steps of one view, as the dense stage runs them over every view
(in this process or in worker processes, :mod:`scenebot.dense.parallel`):

1. :func:`photometric`: coarse-to-fine photometric PatchMatch; writes the view's
   ``*.photometric.bin`` depth, normal and cost maps,
2. :func:`geometric`: geometric-consistency iterations against the sources' photometric
   depth; writes its unfiltered ``*.geometric.bin`` maps,
3. :func:`filtered`: photometric cost and agreement with the sources' unfiltered geometric
   depth; writes the filtered maps to ``stereo/filtered``, which :func:`install_filtered`
   moves over the geometric maps once every view is filtered (the filter of each view reads
   its sources' unfiltered maps).

Each step reads only what the previous step wrote for all views, so the views of a step can
run in any order and any process.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pycolmap

from scenebot.dense import workspace as ws
from scenebot.dense.colmap_io import read_array, write_array
from scenebot.dense.config import PatchMatchConfig
from scenebot.dense.patchmatch import DepthResult, PatchMatchSolver, StereoView
from scenebot.dense.views import ViewPlan

#: views kept loaded per process (a view is the source of a few others, usually near it)
_CACHED_VIEWS = 24
_VIEWS: dict[tuple[str, str], tuple[int, StereoView]] = {}


@dataclass(frozen=True)
class ViewTask:
    """One reference view and its sources.

    Attributes:
        ref: the reference view's camera.
        sources: the sources' cameras, best first.
        planned: per source, whether it gets depth maps of its own (else it gives no
            geometric evidence).
        depth_range: (min, max) z-depth searched, metres.
    """

    ref: ws.ViewCamera
    sources: tuple[ws.ViewCamera, ...]
    planned: tuple[bool, ...]
    depth_range: tuple[float, float]


@dataclass(frozen=True)
class PassSettings:
    """What every view of a step shares: the PatchMatch settings and the workspace."""

    cfg: PatchMatchConfig
    dense_dir: Path


def view_tasks(rec: pycolmap.Reconstruction, plans: list[ViewPlan]) -> list[ViewTask]:
    """The :class:`ViewTask` of every planned view."""
    cams: dict[int, ws.ViewCamera] = {}

    def cam(i: int) -> ws.ViewCamera:
        if i not in cams:
            cams[i] = ws.ViewCamera.of_image(rec, i)
        return cams[i]

    planned = {p.image_id for p in plans}
    tasks = []
    for p in plans:
        srcs = tuple(cam(s) for s in p.sources)
        has_depth = tuple(s in planned for s in p.sources)
        tasks.append(ViewTask(cam(p.image_id), srcs, has_depth, tuple(p.depth_range)))
    return tasks


def _view(dense_dir: Path, cam: ws.ViewCamera) -> StereoView:
    """:func:`~scenebot.dense.workspace.read_view`, the last few views kept (by file time)."""
    path = Path(dense_dir) / "images" / cam.name
    key, stamp = (str(dense_dir), cam.name), path.stat().st_mtime_ns if path.is_file() else -1
    if key in _VIEWS and _VIEWS[key][0] == stamp and stamp >= 0:
        return _VIEWS[key][1]
    view = ws.read_view(dense_dir, cam)
    _VIEWS[key] = (stamp, view)
    while len(_VIEWS) > _CACHED_VIEWS:
        _VIEWS.pop(next(iter(_VIEWS)))
    return view


def _views(task: ViewTask, dense_dir: Path) -> tuple[StereoView, list[StereoView]]:
    return _view(dense_dir, task.ref), [_view(dense_dir, c) for c in task.sources]


def _source_depths(task: ViewTask, dense_dir: Path, stage: str) -> list[np.ndarray]:
    """The sources' depth maps of ``stage``; zeros for a source without depth of its own."""
    out = []
    for c, has_depth in zip(task.sources, task.planned, strict=True):
        if has_depth:
            out.append(ws.read_maps(dense_dir, c.name, stage)[0])
        else:
            out.append(np.zeros((c.height, c.width), np.float32))
    return out


def photometric(task: ViewTask, s: PassSettings) -> dict:
    """The photometric pass of one view; returns its seconds (``photometric_s``)."""
    t0 = time.perf_counter()
    ref, srcs = _views(task, s.dense_dir)
    res = PatchMatchSolver(s.cfg).estimate(ref, srcs, task.depth_range)
    ws.write_maps(s.dense_dir, ref.name, "photometric", res.depth, res.normal)
    write_array(ws.map_path(s.dense_dir, "cost", ref.name, "photometric"), res.photo)
    return {"photometric_s": time.perf_counter() - t0}


def geometric(task: ViewTask, s: PassSettings) -> dict:
    """The geometric pass of one view against its sources' photometric maps (the
    photometric maps themselves with ``geom_iterations: 0``); returns ``geometric_s``."""
    t0 = time.perf_counter()
    name = task.ref.name
    d0, n0 = ws.read_maps(s.dense_dir, name, "photometric")
    if s.cfg.geom_iterations > 0:
        ref, srcs = _views(task, s.dense_dir)
        res = PatchMatchSolver(s.cfg).estimate(
            ref, srcs, task.depth_range,
            src_depths=_source_depths(task, s.dense_dir, "photometric"), init=(d0, n0),
        )  # fmt: skip
    else:
        photo = read_array(ws.map_path(s.dense_dir, "cost", name, "photometric"))
        res = DepthResult(d0, n0, photo, photo)
    # unfiltered geometric maps, so the filter can see every source's estimate
    ws.write_maps(s.dense_dir, name, "geometric", res.depth, res.normal)
    write_array(ws.map_path(s.dense_dir, "cost", name, "geometric"), res.photo)
    return {"geometric_s": time.perf_counter() - t0}


def _filtered_path(dense_dir: Path, kind: str, name: str) -> Path:
    return Path(dense_dir) / "stereo" / "filtered" / f"{name}.{kind}.bin"


def filtered(task: ViewTask, s: PassSettings) -> dict:
    """The filter of one view (photometric cost, agreement with the sources' unfiltered
    geometric depth), written to ``stereo/filtered``; returns ``filter_s`` and
    ``fraction_with_depth``."""
    t0 = time.perf_counter()
    name = task.ref.name
    ref, srcs = _views(task, s.dense_dir)
    d, n = ws.read_maps(s.dense_dir, name, "geometric")
    photo = read_array(ws.map_path(s.dense_dir, "cost", name, "geometric"))
    res = PatchMatchSolver(s.cfg).filter(
        ref, srcs, DepthResult(d, n, photo, photo), _source_depths(task, s.dense_dir, "geometric")
    )
    for kind, arr in (("depth", res.depth), ("normal", res.normal)):
        path = _filtered_path(s.dense_dir, kind, name)
        path.parent.mkdir(parents=True, exist_ok=True)
        write_array(path, arr)
    return {"filter_s": time.perf_counter() - t0,
            "fraction_with_depth": float(np.mean(res.depth > 0))}  # fmt: skip


def install_filtered(dense_dir: Path, names: list[str]) -> None:
    """Move the filtered maps of :func:`filtered` over the views' geometric maps."""
    for name in names:
        for kind in ("depth", "normal"):
            _filtered_path(dense_dir, kind, name).replace(
                ws.map_path(dense_dir, kind, name, "geometric")
            )
    import shutil

    shutil.rmtree(Path(dense_dir) / "stereo" / "filtered", ignore_errors=True)
