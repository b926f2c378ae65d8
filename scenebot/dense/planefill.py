"""Plane completion of the depth maps: plain walls, floors and ceilings (a planar prior).

Photometric stereo finds no depth on plain paint: there is nothing to match (the default
office's walls have a texture contrast of about 3 grey levels against a sensor noise of
1.5). Indoor scenes are mostly planes, and the measured depth around a plain region usually
lies on the plane that spans it (a poster on the wall, the wall's edges, the pattern of the
carpet). This step, between depth estimation and fusion (:func:`plane_fill`; each step is a
module of :mod:`scenebot.dense.planes`, named in brackets):

1. **Planes** (``detect``, ``ceiling``, ``phantoms``): every view's measured (filtered)
   depth is back-projected and thinned to a voxel grid with its stereo normals; planes are
   peeled off the cloud by oriented RANSAC (a point supports a plane only where its normal
   agrees within ``normal_deg``), largest first, while one still holds ``min_plane_share``
   of the points. Each plane keeps its extent: the cells of an in-plane raster that hold
   inliers, closed over gaps. Planes that the measured depth of the views contradicts are
   dropped (``drop_phantoms``): those seen through (more measured depth behind their extent
   than on it), those that lie behind another plane (a slice beneath the floor from a
   repeating carpet), and shadows: of two parallel planes a few centimetres apart
   (``shadow_gap_m``), the one fewer views prefer (each view votes for the plane holding
   more of its measured points; a circle of photos registered 0.2 degrees off puts its wall
   a few cm in front of itself). The ceiling, which a level
   camera sees only in its photos' top rows, at grazing angles, is too small a share of the
   cloud for RANSAC: it is found as the highest dense height of the points with vertical
   normals, above every camera, with nothing measured above it (``ceiling_min_points``,
   :func:`~scenebot.dense.planes.ceiling.find_ceiling`), and it spans the floor's extent.
2. **Extents** (``extents``, with ``extent: carved_hull``): the room's boundary planes
   (walls, floor, ceiling: almost nothing measured past them) span the convex hull of their
   cells, less the cells that measured depth is seen through (a doorway). A plain wall then
   reaches between its posters and corners; a box face keeps its own cells
   (:func:`~scenebot.dense.planes.extents.carved_hulls`). With a ceiling, the walls rise to
   it (``walls_to_ceiling_m``, :func:`~scenebot.dense.planes.extents.span_to_ceiling`: a
   level camera measures the top of a wall only from across the room), and the ceiling
   reaches their top edges (:func:`~scenebot.dense.planes.extents.span_walls`: the floor
   along a wall is often under furniture).
3. **Labels** (``labels``): a measured pixel carries the label of the plane it lies on
   (within ``distance_m`` or ``rel_distance`` of its depth), or "off-plane". An object's
   face that this view sees through (more of its measured depth behind the face than on
   it) is wrong in this view and is not used in it.
4. **Votes** (``labels``): on a grid of ``cell_px`` cells, every cell without measured depth
   looks along 8 directions, up to ``max_gap_frac`` of the image width, for the nearest cell
   with measured depth. With ``fill_rule: bounding_planes`` it is filled when at least
   ``min_votes`` of the found cells, and at least ``min_agreement`` of them, lie on planes,
   and each of its pixels takes the boundary plane its ray meets first (a plain corner
   between two walls and the floor; with ``fill_planes: any_boundary`` any boundary, so a
   plain ceiling above plain walls too); with ``same_plane`` they must all carry the same
   plane label. Either way one bounded by something nearer (a plain cabinet face before a
   wall) is not filled, because its nearest measured neighbours are the cabinet's edges,
   off every plane.
5. **Fill** (``fill``): each hole pixel of a filled cell gets the depth where its ray meets
   the plane (in front of the camera, inside the plane's extent grown by
   ``extent_margin_m``; with ``same_plane`` also within the view's depth range, the sparse
   points' range, which the floor just before the camera lies nearer than) and the plane's
   normal, turned towards the camera. ``passes`` repeat the votes and fill with the fill
   counted as measured: a plain wall's fill spreads to the cells whose neighbours the first
   pass lacked.
6. **Occlusion** (``vetoes``): a filled pixel behind the depth that all views measured,
   projected into this view (``occlusion_min_points`` in its cell), lies behind a surface
   (a plain object the fill spread across) and is emptied again
   (:func:`~scenebot.dense.planes.vetoes.occluded_fill`). So is a fill that the view's own
   SfM points contradict (``sparse_veto``): a close object that stereo missed, whose
   features lie in the photo in front of the wall the fill painted there
   (:func:`~scenebot.dense.planes.vetoes.sparse_contradicted_fill`).

Fusion then needs the usual agreement of ``dense.fusion_min_num_pixels`` views, so a plane
is only fused where several views filled it alike. The measured maps are kept in
``stereo/depth_maps_measured`` for the pictures and for comparison; the planes in
``plane_fill.npz`` (:mod:`~scenebot.dense.planes.store`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scenebot.dense.config import PlaneFillConfig
from scenebot.dense.parallel import ViewPool
from scenebot.dense.planes.ceiling import find_ceiling
from scenebot.dense.planes.detect import LEVEL_DEG, detect_planes, detect_settings, thinned_cloud
from scenebot.dense.planes.extents import carved_hulls, span_floor, span_to_ceiling, span_walls
from scenebot.dense.planes.fill import fill_view, fill_view_settings
from scenebot.dense.planes.geometry import Plane
from scenebot.dense.planes.phantoms import (
    plane_evidence,
    shadow_planes,
    validate_planes,
    view_preferences,
)
from scenebot.dense.planes.store import PLANES_NPZ, save_planes
from scenebot.dense.planes.vetoes import (
    occluded_fill,
    sparse_contradicted_fill,
    sparse_observations,
)

LOG = logging.getLogger(__name__)

#: with ``normal_deg: null`` (planes by position alone) the ceiling search still takes the
#: points whose normals lie within this angle (degrees) of the vertical
CEILING_NORMAL_DEG = 30.0

#: about this many of the views (every ``len(views) // 40``-th; all of them when fewer) count
#: their measured points on and behind the planes for the phantom test; every view counts
#: towards a plane's support
PHANTOM_SAMPLE_VIEWS = 40


def plane_fill(
    dense_dir: Path,
    views: list,
    cfg: PlaneFillConfig,
    progress: bool = True,
    pool: ViewPool | None = None,
) -> dict:
    """Fill every view's geometric depth and normal maps from the scene's planes.

    Args:
        dense_dir: the dense workspace (``stereo/depth_maps/*.geometric.bin`` filtered).
        views: ``(name, K, R, t, depth_range)`` per view.
        cfg: the plane fill's settings.
        progress: show a progress bar.
        pool: the processes that fill the views (default: this one).

    Returns:
        Stats: planes (normal, offset, inliers, extent area), pixels measured and filled per
        view, seconds (``planes_seconds`` of them finding the planes, before the views'
        fill). The measured maps are moved to ``stereo/depth_maps_measured`` (and
        ``normal_maps_measured``) first; a second run starts again from them.
    """
    import time

    t0 = time.perf_counter()
    dense_dir = Path(dense_dir)
    measured = _MeasuredMaps.keep(dense_dir, views)
    centres = np.array([-R.T @ t for _, _, R, t, _ in views])
    # the planes, from every view's measured depth thinned to a voxel grid
    cloud, cloud_n = thinned_cloud(
        ((*measured(name), K, R, t) for name, K, R, t, _ in views),
        np.random.default_rng(cfg.seed),
        points_per_view=cfg.points_per_view,
        voxel_m=cfg.voxel_m,
    )
    planes, ceiling = _find_planes(cloud, cloud_n, centres, cfg)
    dropped: dict[int, str] = {}
    support = prefer = None
    if cfg.drop_phantoms and planes:
        planes, support, prefer, dropped = _drop_phantoms(planes, ceiling, views, measured, cfg)
    if cfg.extent == "carved_hull" and planes:
        _widen_extents(planes, ceiling, views, measured, centres, cfg)
    if cfg.drop_phantoms and cfg.shadow_gap_m > 0 and planes:
        planes = _drop_shadows(planes, support, prefer, dropped, cfg)
    LOG.info("dense: %d planes in %d voxel points", len(planes), len(cloud))
    save_planes(dense_dir / PLANES_NPZ, planes, ceiling, centres)
    t_planes = time.perf_counter() - t0
    per_view, totals = _fill_views(dense_dir, views, planes, cloud, measured, cfg, progress, pool)
    return {
        "planes": [_plane_stats(p) for p in planes],
        "voxel_points": len(cloud),
        "planes_dropped": list(dropped.values()),
        "measured_fraction": totals["measured"] / max(totals["px"], 1),
        "filled_fraction": totals["filled"] / max(totals["px"], 1),
        "culled_fraction": totals["culled"] / max(totals["px"], 1),
        "vetoed_fraction": totals["vetoed"] / max(totals["px"], 1),
        "views": per_view,
        "seconds": time.perf_counter() - t0,
        "planes_seconds": t_planes,
    }


@dataclass
class _MeasuredMaps:
    """The views' measured depth and normal maps (before any fill), kept in
    ``stereo/depth_maps_measured`` and ``normal_maps_measured``; called with a view's name,
    its (depth, normal)."""

    dense_dir: Path
    folders: dict[str, Path]

    @classmethod
    def keep(cls, dense_dir: Path, views: list) -> _MeasuredMaps:
        """Move the views' geometric maps to the ``*_measured`` folders (the fill writes
        every view's geometric maps anew), unless a previous run kept them there already."""
        from scenebot.dense import workspace as ws

        kept = {k: dense_dir / "stereo" / f"{k}_maps_measured" for k in ("depth", "normal")}
        for k, folder in kept.items():
            folder.mkdir(parents=True, exist_ok=True)
            for name, *_ in views:
                src = ws.map_path(dense_dir, k, name, "geometric")
                dst = folder / src.name
                if not dst.is_file():
                    src.replace(dst)  # a rename: 5 MB per view not copied
        return cls(dense_dir, kept)

    def __call__(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        from scenebot.dense import workspace as ws
        from scenebot.dense.colmap_io import read_array

        fname = ws.map_path(self.dense_dir, "depth", name, "geometric").name
        return read_array(self.folders["depth"] / fname), read_array(self.folders["normal"] / fname)


def _find_planes(
    cloud: np.ndarray, cloud_n: np.ndarray, centres: np.ndarray, cfg: PlaneFillConfig
) -> tuple[list[Plane], Plane | None]:
    """The planes RANSAC peels off the cloud and the ceiling (appended to them), if found."""
    planes = detect_planes(
        cloud, normals=cloud_n if cfg.normal_deg is not None else None, **detect_settings(cfg)
    )
    ceiling = None
    if cfg.ceiling_min_points and planes:
        ceiling = find_ceiling(
            cloud, cloud_n, planes, centres, cfg.ransac_distance_m,
            cfg.normal_deg or CEILING_NORMAL_DEG, cfg.ceiling_min_points, cfg.extent_cell_m,
            cfg.extent_min_points, cfg.extent_close_cells,
        )  # fmt: skip
        if ceiling is not None:
            LOG.info("dense: ceiling at %.3f m along %s from %d points", -ceiling.offset,
                     np.round(ceiling.normal, 3).tolist(), ceiling.inliers)  # fmt: skip
            planes.append(ceiling)
    return planes, ceiling


def _evidence(
    planes: list[Plane], views: list, measured: _MeasuredMaps, cfg: PlaneFillConfig
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`~scenebot.dense.planes.phantoms.plane_evidence` summed over a sample of the
    views (``on``, ``behind``, ``hidden``), per plane the number of views that support it
    (``support_min_points`` of their measured points on it), and per pair of planes the
    views that prefer the one to the other
    (:func:`~scenebot.dense.planes.phantoms.view_preferences`)."""
    on = np.zeros(len(planes), np.int64)
    behind = np.zeros(len(planes), np.int64)
    hidden = np.zeros((len(planes), len(planes)), np.int64)
    support = np.zeros(len(planes), np.int64)
    prefer = np.zeros((len(planes), len(planes)), np.int64)
    step = max(1, len(views) // PHANTOM_SAMPLE_VIEWS)
    for k, (name, K, R, t, _) in enumerate(views):
        a, b, c = plane_evidence(measured(name)[0], K, R, t, planes,
                                 distance_m=cfg.label_distance_m,
                                 rel_distance=cfg.label_rel_distance)  # fmt: skip
        support += a >= cfg.support_min_points
        prefer += view_preferences(a, cfg.support_min_points)
        if k % step == 0:
            on, behind, hidden = on + a, behind + b, hidden + c
    return on, behind, hidden, support, prefer


def _drop_phantoms(
    planes: list[Plane], ceiling: Plane | None, views: list, measured: _MeasuredMaps,
    cfg: PlaneFillConfig,
) -> tuple[list[Plane], np.ndarray, np.ndarray, dict[int, str]]:  # fmt: skip
    """The planes the views' measured depth does not contradict (seen through, hidden
    behind another plane; the ceiling is never hidden), their support and the views'
    preferences between them (:func:`_evidence`) and why the others were dropped (by their
    index)."""
    on, behind, hidden, support, prefer = _evidence(planes, views, measured, cfg)
    keep, dropped = validate_planes(
        planes, on, behind, hidden, cfg.max_seen_through, cfg.max_hidden,
        not_hidden=[j for j, p in enumerate(planes) if p is ceiling],
    )  # fmt: skip
    for j, why in dropped.items():
        _log_dropped(j, planes[j], why)
    dropped = {j: _dropped_note(planes[j], w) for j, w in dropped.items()}
    return [planes[j] for j in keep], support[keep], prefer[np.ix_(keep, keep)], dropped


def _drop_shadows(
    planes: list[Plane], support: np.ndarray, prefer: np.ndarray, dropped: dict[int, str],
    cfg: PlaneFillConfig,
) -> list[Plane]:  # fmt: skip
    """The planes without the shadows of those the views prefer; why those were dropped is
    added to ``dropped`` (keys from 1000 on)."""
    shadows = shadow_planes(planes, support, cfg.shadow_gap_m, max_angle_deg=cfg.merge_angle_deg,
                            prefer=prefer)  # fmt: skip
    for j, why in shadows.items():
        _log_dropped(j, planes[j], why)
        dropped[len(dropped) + 1000 + j] = _dropped_note(planes[j], why)
    return [p for j, p in enumerate(planes) if j not in shadows]


def _log_dropped(j: int, plane: Plane, why: str) -> None:
    LOG.info("dense: plane %d (normal %s) dropped, %s", j,
             np.round(plane.normal, 2).tolist(), why)  # fmt: skip


def _dropped_note(plane: Plane, why: str) -> str:
    """A dropped plane and why, for the summary's ``planes_dropped``."""
    return f"normal {np.round(plane.normal, 3).tolist()}, offset {plane.offset:.3f}: {why}"


def _widen_extents(
    planes: list[Plane], ceiling: Plane | None, views: list, measured: _MeasuredMaps,
    centres: np.ndarray, cfg: PlaneFillConfig,
) -> None:  # fmt: skip
    """Widen the extents of the room's boundary planes (in place): their carved hulls, the
    floor to the walls (``floor_to_walls``), the walls to the ceiling and the ceiling to the
    floor and the walls."""
    samples = ((measured(name)[0], K, R, t) for name, K, R, t, _ in views)  # one at a time
    hulls = carved_hulls(
        planes,
        samples,
        distance_m=cfg.label_distance_m,
        rel_distance=cfg.label_rel_distance,
        min_rays=cfg.carve_min_rays,
        known=[j for j, p in enumerate(planes) if p is ceiling],  # the room's top
    )
    for pl, ext in zip(planes, hulls, strict=True):
        pl.occupied = ext
    # the room's boundary planes other than the ceiling (span_walls keeps the upright ones)
    walls = [p for p in planes if p is not ceiling and p.boundary]
    if cfg.floor_to_walls:
        _floor_to_walls(walls, centres)
    if ceiling is not None and any(p is ceiling for p in planes) and ceiling.boundary:
        level = [p for p in walls if abs(p.normal @ ceiling.normal) > 0.999]
        if level:  # the floor: the largest boundary plane parallel to the ceiling
            span_floor(ceiling, max(level, key=lambda p: p.inliers))
        if cfg.walls_to_ceiling_m > 0:
            for p in walls:
                span_to_ceiling(p, ceiling, max_rise_m=cfg.walls_to_ceiling_m)
            span_walls(ceiling, walls)


def _floor_to_walls(walls: list[Plane], centres: np.ndarray) -> None:
    """Widen the floor (the largest level boundary plane below the cameras) to the walls."""
    up = np.array([0.0, 0.0, 1.0])  # the map's z axis (sfm: robot frame, z up)
    level = [p for p in walls if abs(p.normal @ up) > np.cos(np.radians(LEVEL_DEG))]
    if level:  # the floor: the largest level boundary plane below the cameras
        floor = max(level, key=lambda p: p.inliers)
        if np.median(centres @ floor.normal + floor.offset) * (floor.normal @ up) > 0:
            span_walls(floor, walls, centres=centres)


@dataclass(frozen=True)
class _FillShared:
    """What every view's fill shares (handed once to each worker process)."""

    dense_dir: Path
    planes: list[Plane]
    cloud: np.ndarray
    measured: _MeasuredMaps
    observed: dict[str, tuple[np.ndarray, np.ndarray]]
    cfg: PlaneFillConfig


def _fill_views(
    dense_dir: Path, views: list, planes: list[Plane], cloud: np.ndarray,
    measured: _MeasuredMaps, cfg: PlaneFillConfig, progress: bool, pool: ViewPool | None,
) -> tuple[list[dict], dict[str, int]]:  # fmt: skip
    """Fill every view's maps from the planes and write them as its geometric maps (the
    views spread over the pool's workers, if given).

    Returns:
        Per view its name and the shares of its pixels measured, filled, culled and vetoed;
        the pixels of all views together (``px``) and those counts summed.
    """
    observed: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    if cfg.sparse_veto and (dense_dir / "sparse").is_dir():
        observed = sparse_observations(dense_dir / "sparse")
    names = {name for name, *_ in views}
    shared = _FillShared(dense_dir, planes, cloud, measured,
                         {k: v for k, v in observed.items() if k in names}, cfg)  # fmt: skip
    if pool is None:
        pool = ViewPool(1, cfg.seed, dense_dir)
    counts = pool.map(_fill_and_write, views, shared, progress="plane fill" if progress else None)
    per_view = []
    totals = dict.fromkeys(("px", "measured", "filled", "culled", "vetoed"), 0)
    for (name, *_), c in zip(views, counts, strict=True):
        px = c.pop("px")
        per_view.append({"name": name, **{k: c[k] / px for k in
                                          ("measured", "filled", "culled", "vetoed")}})  # fmt: skip
        totals["px"] += px
        for k, v in c.items():
            totals[k] += v
    return per_view, totals


def _fill_and_write(view: tuple, s: _FillShared) -> dict[str, int]:
    """One view's fill (:func:`_fill_one_view`) written as its geometric maps; its pixels
    (``px``) and those measured, filled, culled and vetoed."""
    from scenebot.dense import workspace as ws
    from scenebot.dense.colmap_io import write_array

    name, K, R, t, rng_d = view
    d, n = s.measured(name)
    fd, fn, counts = _fill_one_view(d, n, K, R, t, rng_d, s.planes, s.cloud,
                                    s.observed.get(name), s.cfg)  # fmt: skip
    write_array(ws.map_path(s.dense_dir, "depth", name, "geometric"), fd)
    write_array(ws.map_path(s.dense_dir, "normal", name, "geometric"), fn)
    return {"px": d.size, "measured": int((d > 0).sum()), **counts}


def _fill_one_view(
    d: np.ndarray, n: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray,
    depth_range: tuple[float, float], planes: list[Plane], cloud: np.ndarray,
    observed: tuple[np.ndarray, np.ndarray] | None, cfg: PlaneFillConfig,
) -> tuple[np.ndarray, np.ndarray, dict[str, int]]:  # fmt: skip
    """One view's measured maps (d, n) filled in ``cfg.passes`` passes, less the fill
    behind the measured cloud and the fill its SfM points (``observed``: positions as
    fractions of the image size, depths) contradict; with the pixels filled, culled and
    vetoed."""
    fd, fn, filled, culled = d, n, 0, 0
    cache: dict = {}
    for k in range(cfg.passes):  # a later pass counts the fill as measured: it spreads
        fd, fn, more, cut = fill_view(fd, fn, K, R, t, planes, depth_range,
                                      **fill_view_settings(cfg, first_pass=k == 0),
                                      cache=cache)  # fmt: skip
        filled, culled = filled + more, culled + cut
        if not more:
            break
    if cfg.occlusion_min_points and filled:
        bad = occluded_fill(fd, (fd > 0) & ~(d > 0), K, R, t, cloud, cell_px=cfg.cell_px,
                            min_points=cfg.occlusion_min_points)  # fmt: skip
        fd[bad], fn[bad] = 0, 0
        filled -= int(bad.sum())
    vetoed = 0
    if filled and observed is not None:
        uv_obs, z_obs = observed
        uv_obs = uv_obs * fd.shape[::-1]
        bad = sparse_contradicted_fill(fd, (fd > 0) & ~(d > 0), uv_obs, z_obs,
                                       max_edge_px=cfg.sparse_veto_max_edge_px)  # fmt: skip
        fd[bad], fn[bad] = 0, 0
        vetoed = int(bad.sum())
        filled -= vetoed
    return fd, fn, {"filled": filled, "culled": culled, "vetoed": vetoed}


def _plane_stats(p: Plane) -> dict:
    """A plane for the summary: normal, offset, inliers and extent area, rounded."""
    return {"normal": p.normal.round(4).tolist(), "offset": round(p.offset, 4),
            "inliers": p.inliers, "area_m2": round(p.area_m2, 3)}  # fmt: skip
