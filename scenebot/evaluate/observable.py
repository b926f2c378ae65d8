"""The observable surface of a simulated scene: what completeness counts (evaluation only).

No method can reconstruct surface that no photo the robot could take would show, so the
completeness of a model is measured against the *observable surface*: the part of the true
mesh visible from some reachable robot pose, with the camera at its mounted height.

Definition (computed by :func:`observable_surface`):

1. **Reachable positions**: the simulator's collision map (geometry between the floor +
   ``body.clearance_m`` and ``body.height_m``, see :class:`~scenebot.sim.obstacles.ObstacleMap`),
   cells with clearance >= the robot radius, and of those the 4-connected region containing
   the start position (:func:`reachable_mask`).
2. **Viewpoints**: robot positions on a square grid (``grid_step_m``) inside that region, each
   with ``headings`` evenly spaced headings; the camera centre and orientation follow the
   simulator's mount (height, forward and lateral offset, pitch) and its pinhole camera
   (width, height, horizontal field of view) (:func:`sample_viewpoints`).
3. **Surface samples**: every triangle of the true mesh gets ``max(1, round(area /
   spacing^2))`` area-uniform random points, each weighted by ``area / n`` (m^2), so small
   parts (legs, frames) are represented and weights sum to the mesh's area
   (:func:`sample_surface_weighted`).
4. **Visibility**: a sample is observable when some viewpoint has it inside its image, in
   front of the camera, within ``max_range_m`` (if set), seen at an incidence angle below
   ``max_incidence_deg`` from the surface normal, and the ray from the camera centre hits
   nothing before it (open3d ray casting; :func:`observable_mask`).

The result is written to a ``.npz`` file that records its key: a hash of the geometry and
every setting above (:func:`cache_key`), and drawn top-down (:func:`plot_observable`).
:func:`load_or_compute` re-uses that file while its key matches, and keeps a copy in a cache
shared by campaigns (``evaluate.cache_dir``), one file per key, named by the key's hash
(:func:`cache_file`): every campaign of a scene with the same settings (the suite's scene,
its baselines, the tests) reads it instead of computing it again.
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import os
import shutil
import uuid
import zipfile
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

import cv2
import numpy as np

from scenebot.evaluate.config import EvaluateConfig
from scenebot.geometry import Intrinsics, look_rotation
from scenebot.robot.base import Pose2D
from scenebot.robot.factory import start_pose
from scenebot.scene.mesh import SceneMesh
from scenebot.sim.obstacles import ObstacleMap

log = logging.getLogger(__name__)

CACHE_VERSION = 2


class ObservableError(ValueError):
    """The observable surface cannot be computed; the message says which setting to fix."""


@dataclass
class Viewpoints:
    """Sampled reachable camera poses.

    Attributes:
        robot_xy: (P, 2) robot positions (m, world frame), one per pose.
        headings: (P,) robot headings (rad, CCW from +x).
        centers: (P, 3) camera centres (m, world frame).
        R: (P, 3, 3) cam_from_world rotations (OpenCV camera axes).
        intrinsics: the pinhole camera.
    """

    robot_xy: np.ndarray
    headings: np.ndarray
    centers: np.ndarray
    R: np.ndarray
    intrinsics: Intrinsics


@dataclass
class ObservableSurface:
    """Surface samples of the true mesh and which of them are observable.

    Attributes:
        points: (M, 3) float64 samples on the true mesh (m, world frame).
        weights: (M,) float64 area each sample stands for (m^2); sums to the mesh area.
        triangle: (M,) int32 triangle each sample lies on.
        observable: (M,) bool, seen from some reachable viewpoint.
        positions: (P, 2) reachable robot positions used as viewpoints (m).
        reachable: dict with the reachable-region raster: ``origin`` (2,), ``res`` (m),
            ``mask`` (H, W) bool (for pictures).
        meta: settings, scene name, cache key, summary figures.
    """

    points: np.ndarray
    weights: np.ndarray
    triangle: np.ndarray
    observable: np.ndarray
    positions: np.ndarray
    reachable: dict
    meta: dict = field(default_factory=dict)

    @property
    def observable_points(self) -> np.ndarray:
        """(K, 3) the observable samples."""
        return self.points[self.observable]

    @property
    def observable_weights(self) -> np.ndarray:
        """(K,) their areas (m^2)."""
        return self.weights[self.observable]

    def summary(self) -> dict:
        """Areas (m^2), counts and the observable fraction of the area."""
        total = float(self.weights.sum())
        seen = float(self.weights[self.observable].sum())
        return {
            "total_area_m2": total,
            "observable_area_m2": seen,
            "observable_fraction": seen / total if total > 0 else 0.0,
            "samples": len(self.points),
            "observable_samples": int(self.observable.sum()),
            "viewpoint_positions": len(self.positions),
        }

    def save(self, path: Path) -> Path:
        """Write the ``.npz`` file (points as float32 to keep it small), atomically."""
        return _write_atomic(Path(path), self._dump)

    def _dump(self, fh: BinaryIO) -> None:
        np.savez_compressed(
            fh,
            points=self.points.astype(np.float32),
            weights=self.weights.astype(np.float32),
            triangle=self.triangle.astype(np.int32),
            observable=self.observable,
            positions=self.positions.astype(np.float32),
            reach_origin=np.asarray(self.reachable["origin"], np.float64),
            reach_res=np.float64(self.reachable["res"]),
            reach_mask=np.packbits(self.reachable["mask"], axis=1),
            reach_width=np.int64(self.reachable["mask"].shape[1]),
            meta=np.array(json.dumps(self.meta, sort_keys=True)),
        )

    @staticmethod
    def load(path: Path) -> ObservableSurface:
        """Read a file written by :meth:`save`."""
        path = Path(path)
        try:
            with np.load(path) as z:
                width = int(z["reach_width"])
                return ObservableSurface(
                    points=z["points"].astype(np.float64),
                    weights=z["weights"].astype(np.float64),
                    triangle=z["triangle"],
                    observable=z["observable"].astype(bool),
                    positions=z["positions"].astype(np.float64),
                    reachable={
                        "origin": z["reach_origin"],
                        "res": float(z["reach_res"]),
                        "mask": np.unpackbits(z["reach_mask"], axis=1)[:, :width].astype(bool),
                    },
                    meta=json.loads(str(z["meta"])),
                )
        except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
            raise ObservableError(
                f"observable-surface file {path} is unreadable ({exc}); delete it to recompute"
            ) from exc


# ------------------------------------------------------------------------------ reachability
def collision_map(scene: SceneMesh, sim_cfg) -> ObstacleMap:
    """The simulator's collision map of ``scene`` (same band as :class:`SimWorld` uses)."""
    body = sim_cfg.body
    return ObstacleMap.build(scene, scene.floor_z + body.clearance_m, scene.floor_z + body.height_m)


def reachable_mask(cmap: ObstacleMap, start_xy, radius_m: float) -> np.ndarray:
    """Cells the robot's centre can reach from the start without touching geometry.

    Args:
        cmap: the collision map.
        start_xy: (2,) start position (m, world frame).
        radius_m: robot footprint radius (m).

    Returns:
        (H, W) bool, True in the 4-connected region of cells with clearance >= ``radius_m``
        that contains the start cell.

    Raises:
        ObservableError: the start position is not free for the robot.
    """
    free = cmap.clearance >= radius_m
    r, c = cmap._cell(start_xy)
    if not free[r, c]:
        raise ObservableError(
            f"start position ({start_xy[0]:.2f}, {start_xy[1]:.2f}) m has clearance "
            f"{cmap.clearance[r, c]:.3f} m < robot radius {radius_m:.3f} m: set world.start "
            "in config.yaml to a free spot"
        )
    _, labels = cv2.connectedComponents(free.astype(np.uint8), connectivity=4)
    return labels == labels[r, c]


def sample_viewpoints(
    cmap: ObstacleMap,
    reach: np.ndarray,
    grid_step_m: float,
    headings: int,
    camera_cfg,
    floor_z: float,
) -> Viewpoints:
    """Camera poses on a grid of reachable robot positions, ``headings`` each.

    Args:
        cmap: the collision map (its raster geometry).
        reach: (H, W) bool reachable cells (:func:`reachable_mask`).
        grid_step_m: spacing of the positions (m); the grid is anchored at the map origin.
        headings: headings per position, evenly spaced from 0.
        camera_cfg: :class:`~scenebot.config.CameraConfig` (mount and pinhole).
        floor_z: floor height (m).

    Returns:
        The viewpoints; positions x headings poses.
    """
    h, w = reach.shape
    step = max(1, round(grid_step_m / cmap.res))
    rows, cols = np.mgrid[step // 2 : h : step, step // 2 : w : step]
    ok = reach[rows, cols]
    xy = cmap.origin + np.c_[cols[ok], rows[ok]] * cmap.res
    ths = np.arange(headings) * 2 * math.pi / headings
    xy_all = np.repeat(xy, headings, axis=0)
    th_all = np.tile(ths, len(xy))
    c, s = np.cos(th_all), np.sin(th_all)
    f, lat = camera_cfg.forward_offset_m, camera_cfg.lateral_offset_m
    centers = np.c_[
        xy_all[:, 0] + f * c - lat * s,
        xy_all[:, 1] + f * s + lat * c,
        np.full(len(th_all), floor_z + camera_cfg.height_m),
    ]
    pitch = math.radians(camera_cfg.pitch_deg)
    R = np.array([look_rotation(t, pitch) for t in th_all]).reshape(-1, 3, 3)
    intr = Intrinsics.from_hfov(camera_cfg.width, camera_cfg.height, camera_cfg.hfov_deg)
    return Viewpoints(xy_all, th_all, centers, R, intr)


# --------------------------------------------------------------------------- surface samples
def triangle_normals(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(T, 3) unit normals and (T,) areas (m^2) of a mesh."""
    v = np.asarray(vertices, np.float64)[np.asarray(triangles)]
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    norm = np.linalg.norm(n, axis=1)
    return n / np.maximum(norm, 1e-15)[:, None], 0.5 * norm


def sample_surface_weighted(
    vertices: np.ndarray,
    triangles: np.ndarray,
    spacing_m: float,
    *,
    seed: int,
    max_samples: int = 20_000_000,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Area-stratified random samples of a triangle mesh.

    Args:
        vertices: (V, 3) metres.
        triangles: (T, 3) indices.
        spacing_m: mean spacing (m): triangle i gets ``max(1, round(area_i / spacing^2))``.
        seed: random seed (``evaluate.seed``).
        max_samples: refuse to draw more (raise ``spacing_m`` instead).

    Returns:
        ``points`` (M, 3) float64, ``weights`` (M,) float64 area per sample (m^2; they sum to
        the total area of non-degenerate triangles), ``triangle`` (M,) int32.

    Raises:
        ObservableError: more than ``max_samples`` would be drawn.
    """
    v = np.asarray(vertices, np.float64)
    tri = np.asarray(triangles, np.int64)
    _, area = triangle_normals(v, tri)
    keep = area > 1e-12
    counts = np.where(keep, np.maximum(1, np.round(area / spacing_m**2)), 0).astype(np.int64)
    total = int(counts.sum())
    if total > max_samples:
        raise ObservableError(
            f"{total} surface samples at evaluate.sample_spacing_m={spacing_m} m exceed "
            f"{max_samples}: raise evaluate.sample_spacing_m"
        )
    rng = np.random.default_rng(seed)
    tid = np.repeat(np.arange(len(tri)), counts)
    r1, r2 = rng.random(total), rng.random(total)
    s1 = np.sqrt(r1)
    a, b, c = (v[tri[tid, k]] for k in range(3))
    pts = (1 - s1)[:, None] * a + (s1 * (1 - r2))[:, None] * b + (s1 * r2)[:, None] * c
    weights = (area / np.maximum(counts, 1))[tid]
    return pts, weights, tid.astype(np.int32)


# -------------------------------------------------------------------------------- visibility
def _half_diagonal_fov(intr: Intrinsics) -> float:
    """Half angle of the image diagonal, plus 0.5 deg: no pixel's ray is farther from the
    optical axis (rad)."""
    diag = math.atan(math.hypot(intr.width / 2 / intr.fx, intr.height / 2 / intr.fy))
    diag += math.radians(0.5)
    return diag


def _robot_positions(views: Viewpoints, seed: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Group the poses by robot position.

    Returns:
        The positions' group numbers in a seeded random order, (P,) the group of each pose,
        and the largest offset of a camera centre from its robot's axis (m, plus 1 um).
    """
    _, first, group = np.unique(views.robot_xy, axis=0, return_index=True, return_inverse=True)
    group = group.ravel()
    offs = np.linalg.norm(views.centers[:, :2] - views.robot_xy, axis=1)
    r_off = float(offs.max()) + 1e-6
    order = np.random.default_rng(seed).permutation(len(first))
    return order, group, r_off


@dataclass
class _Nearby:
    """The unseen points that some heading at one robot position may have in its image.

    Attributes:
        idx: (N,) point indices.
        az: (N,) their azimuths from the robot's position (rad), or None for pitched cameras
            (no azimuth bound).
        margin: (N,) azimuth widening (rad) for the camera centre's offset from the axis.
    """

    idx: np.ndarray
    az: np.ndarray | None = None
    margin: np.ndarray | None = None

    def for_heading(self, R: np.ndarray, seen: np.ndarray, diag: float) -> np.ndarray:
        """The points still unseen that the view ``R`` (cam_from_world) may have in its image."""
        if self.az is None:
            return self.idx[~seen[self.idx]]
        fwd = R[2]
        da = np.abs((self.az - math.atan2(fwd[1], fwd[0]) + np.pi) % (2 * np.pi) - np.pi)
        sub = self.idx[da <= diag + self.margin]
        return sub[~seen[sub]]


def _nearby(
    pts: np.ndarray,
    idx: np.ndarray,
    views: Viewpoints,
    poses: np.ndarray,
    diag: float,
    r_off: float,
    max_range_m: float | None,
) -> _Nearby:
    """Keep the points ``idx`` whose elevation (and range) some pose of ``poses`` (one robot
    position) can see: a conservative bound over all its headings."""
    base = np.r_[views.robot_xy[poses[0]], views.centers[poses[0], 2]]
    d0 = pts[idx] - base
    dh = np.hypot(d0[:, 0], d0[:, 1])
    # elevation closest to the horizon over all camera centres within r_off of the axis
    elev = np.arctan2(d0[:, 2], dh + r_off)
    pitches = [math.asin(np.clip(views.R[k][2, 2], -1, 1)) for k in poses]
    band = (elev <= max(pitches) + diag) & (elev >= min(pitches) - diag)
    if max_range_m is not None:
        band &= np.hypot(dh, d0[:, 2]) <= max_range_m + r_off
    idx = idx[band]
    level = max(abs(p) for p in pitches) < 1e-9
    if idx.size == 0 or not level:
        return _Nearby(idx)
    # azimuth bound (valid for level cameras: |azimuth offset| <= hfov / 2)
    az = np.arctan2(d0[band, 1], d0[band, 0])
    dhb = dh[band]
    # the camera centre is up to r_off off the axis: widen by asin(r_off / distance)
    margin = np.arcsin(np.clip(r_off / np.maximum(dhb, 1e-9), 0.0, 1.0))
    margin[dhb <= 2 * r_off] = np.pi
    return _Nearby(idx, az, margin)


@dataclass
class _ViewTest:
    """The exact test of whether one view sees points: framing, range, incidence, occlusion.

    Attributes:
        pts: (M, 3) surface points (m).
        normals: (M, 3) their unit normals.
        intr: the pinhole camera.
        raycaster: an ``open3d.t.geometry.RaycastingScene`` of the mesh.
        near_m: nearer points (along the camera axis) are not seen.
        max_range_m: farther points are not seen (None: no limit).
        cos_max: cosine of the largest incidence angle (-1: any angle).
        point_triangle: (M,) triangle of each point, or None (then any surface within 3 mm
            of the point counts as the point).
        triangle_normals_: (T, 3) unit normals of the mesh's triangles (with
            ``point_triangle``).
    """

    pts: np.ndarray
    normals: np.ndarray
    intr: Intrinsics
    raycaster: object
    near_m: float
    max_range_m: float | None
    cos_max: float
    point_triangle: np.ndarray | None
    triangle_normals_: np.ndarray | None

    def visible(self, sub: np.ndarray, c: np.ndarray, R: np.ndarray) -> np.ndarray:
        """The points of ``sub`` that the view (centre ``c``, cam_from_world ``R``) sees."""
        d = self.pts[sub] - c
        inside, dist = self._framed(sub, d, R)
        cand = np.flatnonzero(inside)
        if cand.size == 0:
            return cand
        vis = self._unoccluded(sub[cand], c, d[cand], dist[cand])
        return sub[cand[vis]]

    def _framed(self, sub: np.ndarray, d: np.ndarray, R: np.ndarray):
        """Inside the image, in front of the camera, in range, not too oblique: (mask,
        distances) of the points ``sub`` at offsets ``d`` from the camera centre."""
        intr = self.intr
        pc = d @ R.T
        z = pc[:, 2]
        inside = z > self.near_m
        zi = np.where(inside, z, 1.0)
        u = intr.fx * pc[:, 0] / zi + intr.cx
        v = intr.fy * pc[:, 1] / zi + intr.cy
        inside &= (u >= 0) & (u < intr.width) & (v >= 0) & (v < intr.height)
        dist = np.linalg.norm(d, axis=1)
        if self.max_range_m is not None:
            inside &= dist <= self.max_range_m
        if self.cos_max > -1.0:
            cos_inc = np.abs(np.sum(self.normals[sub] * d, axis=1)) / np.maximum(dist, 1e-12)
            inside &= cos_inc >= self.cos_max
        return inside, dist

    def _unoccluded(self, sub: np.ndarray, c: np.ndarray, d: np.ndarray, dist: np.ndarray):
        """Which points ``sub`` (offsets ``d``, distances ``dist``) the ray from ``c`` reaches
        (see :func:`observable_mask`)."""
        import open3d as o3d

        dirs = d / dist[:, None]
        rays = np.concatenate([np.broadcast_to(c, dirs.shape), dirs], axis=1)
        ans = self.raycaster.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))
        thit = ans["t_hit"].numpy()
        vis = thit >= dist - np.maximum(0.003, 1e-3 * dist)
        if self.point_triangle is not None and self.triangle_normals_ is not None:
            prim = ans["primitive_ids"].numpy().astype(np.int64)
            own = self.point_triangle[sub]
            tn = self.triangle_normals_
            hit = np.clip(prim, 0, len(tn) - 1)
            parallel = np.abs(np.sum(tn[hit] * self.normals[sub], 1)) > 0.999
            vis = (prim == own) | (vis & parallel)
        return vis


def observable_mask(
    points: np.ndarray,
    normals: np.ndarray,
    views: Viewpoints,
    raycaster,
    *,
    max_range_m: float | None,
    max_incidence_deg: float,
    seed: int,
    near_m: float = 0.05,
    point_triangle: np.ndarray | None = None,
    triangle_normals_: np.ndarray | None = None,
) -> np.ndarray:
    """Which points some viewpoint sees (in its image, unoccluded, not too oblique).

    Occlusion: the ray from the camera centre to the point must first hit the point's own
    triangle, or a surface parallel to it no nearer than the point minus 3 mm (the other
    triangle of a quad, a coplanar face). Without ``point_triangle`` any surface within 3 mm
    of the point counts, which lets a point within a few mm of a box edge be seen through the
    adjacent face.

    Positions are visited in a seeded random order and only points not yet seen are tested.
    At each position, points whose elevation or azimuth no heading's image can contain (a
    conservative bound with the diagonal half field of view and the camera's offset from the
    robot's axis) are skipped before the exact per-view test and the ray cast, so the cost
    is dominated by the surface that is finally not observable but inside the field of view.

    Args:
        points: (M, 3) surface points (m).
        normals: (M, 3) unit surface normals (either orientation: surfaces are two-sided).
        views: the viewpoints (consecutive poses sharing a robot position are grouped).
        raycaster: an ``open3d.t.geometry.RaycastingScene`` of the same mesh.
        max_range_m: farther points are not seen (None: no limit; ``evaluate.max_range_m``).
        max_incidence_deg: points seen more obliquely (angle between the ray and the normal)
            are not seen (``evaluate.max_incidence_deg``).
        seed: seed of the visiting order (``evaluate.seed``).
        near_m: points closer to the camera than this (along its axis) are not seen.
        point_triangle: (M,) triangle index of each point (in the raycaster's mesh).
        triangle_normals_: (T, 3) unit normals of the mesh's triangles (with
            ``point_triangle``).

    Returns:
        (M,) bool.
    """
    pts = np.asarray(points, np.float64)
    seen = np.zeros(len(pts), bool)
    cos_max = math.cos(math.radians(max_incidence_deg)) if max_incidence_deg < 90 else -1.0
    test = _ViewTest(
        pts=pts,
        normals=normals,
        intr=views.intrinsics,
        raycaster=raycaster,
        near_m=near_m,
        max_range_m=max_range_m,
        cos_max=cos_max,
        point_triangle=point_triangle,
        triangle_normals_=triangle_normals_,
    )
    diag = _half_diagonal_fov(views.intrinsics)
    if len(views.centers) == 0:
        return seen
    order, group, r_off = _robot_positions(views, seed)
    for g in order:
        idx = np.flatnonzero(~seen)
        if idx.size == 0:
            break
        poses = np.flatnonzero(group == g)
        nearby = _nearby(pts, idx, views, poses, diag, r_off, max_range_m)
        if nearby.idx.size == 0:
            continue
        for k in poses:
            sub = nearby.for_heading(views.R[k], seen, diag)
            if sub.size:
                seen[test.visible(sub, views.centers[k], views.R[k])] = True
    return seen


# ------------------------------------------------------------------------------------ driver
def _scene_hash(scene: SceneMesh) -> str:
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(scene.vertices, np.float64).tobytes())
    h.update(np.ascontiguousarray(scene.triangles, np.int32).tobytes())
    h.update(repr(float(scene.floor_z)).encode())
    return h.hexdigest()[:16]


def cache_key(scene: SceneMesh, sim_cfg, ecfg: EvaluateConfig, start: Pose2D) -> dict:
    """Everything the observable surface depends on (stored in the file, compared on load)."""
    return {
        "version": CACHE_VERSION,
        "scene": scene.name,
        "scene_hash": _scene_hash(scene),
        "start_xy": [round(start.x, 4), round(start.y, 4)],
        "body": sim_cfg.body.model_dump(
            mode="json", include={"radius_m", "height_m", "clearance_m"}
        ),
        "camera": sim_cfg.camera.model_dump(
            mode="json",
            include={
                "width",
                "height",
                "hfov_deg",
                "height_m",
                "forward_offset_m",
                "lateral_offset_m",
                "pitch_deg",
            },
        ),
        "evaluate": ecfg.model_dump(
            mode="json",
            include={
                "grid_step_m",
                "headings",
                "sample_spacing_m",
                "max_range_m",
                "max_incidence_deg",
                "seed",
            },
        ),
    }


def observable_surface(
    scene: SceneMesh,
    sim_cfg,
    ecfg: EvaluateConfig,
    start: Pose2D | None = None,
    world_cfg=None,
) -> ObservableSurface:
    """Compute the observable surface of a scene (see the module docstring).

    Args:
        scene: the true scene (world frame).
        sim_cfg: :class:`~scenebot.config.SimConfig` (robot body and camera mount).
        ecfg: evaluation settings.
        start: start pose; None: as the capture stage picks it (``world_cfg.start``, the
            scene's default, or the freest cell).
        world_cfg: :class:`~scenebot.config.WorldConfig`, for its ``start``.

    Returns:
        The samples, their weights and visibility, with a summary in ``meta``.
    """
    from scenebot.dense.evaluate import mesh_raycaster

    cmap = collision_map(scene, sim_cfg)
    if start is None:
        start = start_pose(scene, world_cfg, cmap)
    reach = reachable_mask(cmap, (start.x, start.y), sim_cfg.body.radius_m)
    views = sample_viewpoints(
        cmap, reach, ecfg.grid_step_m, ecfg.headings, sim_cfg.camera, scene.floor_z
    )
    if len(views.centers) == 0:
        raise ObservableError(
            f"no reachable position on the {ecfg.grid_step_m} m grid in scene {scene.name!r}: "
            "lower evaluate.grid_step_m"
        )
    pts, weights, tid = sample_surface_weighted(
        scene.vertices, scene.triangles, ecfg.sample_spacing_m, seed=ecfg.seed
    )
    normals, _ = triangle_normals(scene.vertices, scene.triangles)
    rc = mesh_raycaster(scene.vertices, scene.triangles)
    seen = observable_mask(
        pts, normals[tid], views, rc, max_range_m=ecfg.max_range_m,
        max_incidence_deg=ecfg.max_incidence_deg, seed=ecfg.seed, point_triangle=tid,
        triangle_normals_=normals,
    )  # fmt: skip
    positions = views.robot_xy[:: ecfg.headings]
    surf = ObservableSurface(
        pts, weights, tid, seen, positions,
        {"origin": cmap.origin, "res": cmap.res, "mask": reach},
        meta=cache_key(scene, sim_cfg, ecfg, start),
    )  # fmt: skip
    surf.meta["summary"] = surf.summary()
    surf.meta["reachable_area_m2"] = float(reach.sum() * cmap.res**2)
    return surf


@dataclass(frozen=True)
class Provenance:
    """Where :func:`load_or_compute` got the observable surface.

    Attributes:
        source: ``"output"`` (the file at its path, whose key matched), ``"cache"`` (the
            shared cache's file, copied to the path) or ``"computed"``.
        key_hash: the key's hash (:func:`key_hash`).
        cache_file: the shared cache's file of the key (:func:`cache_file`); None when the
            cache is off (``evaluate.cache_dir: ''``).
    """

    source: str
    key_hash: str
    cache_file: Path | None

    @property
    def cached(self) -> bool:
        """Read from a file (the output's or the shared cache's), not computed."""
        return self.source != "computed"

    def as_dict(self) -> dict:
        """``cached``, ``source``, ``key_hash`` and ``cache_file`` (a string or None)."""
        return {
            "cached": self.cached,
            "source": self.source,
            "key_hash": self.key_hash,
            "cache_file": None if self.cache_file is None else str(self.cache_file),
        }


def key_hash(key: dict) -> str:
    """sha256 (hex) of a :func:`cache_key` as sorted, compact JSON (it holds the
    ``CACHE_VERSION``)."""
    text = json.dumps(key, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def cache_file(folder: Path, key: dict) -> Path:
    """The shared cache's file of ``key`` in the cache folder ``folder``
    (:meth:`~scenebot.evaluate.config.EvaluateConfig.cache_folder`)."""
    return Path(folder) / "observable" / f"observable_surface-v{CACHE_VERSION}-{key_hash(key)}.npz"


def _write_atomic(path: Path, write: Callable[[BinaryIO], None]) -> Path:
    """Write ``path`` through ``write`` into a temporary file of its own folder, then rename
    it (``os.replace``): a reader, or another process writing the same file at once, never
    sees a half-written file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp")
    try:
        with open(tmp, "xb") as fh:
            write(fh)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def _copy_atomic(src: Path, dst: Path) -> Path:
    """Copy ``src`` to ``dst`` atomically (:func:`_write_atomic`).

    A copy, not a hard link: Snakemake touches a job's outputs when it ends, and through a
    hard link that would touch the shared file and every other campaign's output linked to
    it, whose later rules would then look out of date. The file is a few MB.
    """
    with open(src, "rb") as f:
        return _write_atomic(Path(dst), lambda fh: shutil.copyfileobj(f, fh, 1 << 20))


def _matches(surf: ObservableSurface, key: dict) -> bool:
    return {k: surf.meta.get(k) for k in key} == key


def _is_file(path: Path) -> bool:
    """Whether ``path`` is a file; False when it cannot be checked (a warning)."""
    try:
        return path.is_file()
    except OSError as exc:
        log.warning("shared cache file %s cannot be checked (%s)", path, exc)
        return False


def _from_cache(shared: Path, key: dict) -> ObservableSurface | None:
    """The shared cache's surface of ``key``, or None (absent; unreadable or another key:
    a warning naming the file, and the caller computes it and replaces the file)."""
    if not _is_file(shared):
        return None
    try:
        surf = ObservableSurface.load(shared)
    except ObservableError as exc:
        log.warning("shared cache file %s is unreadable (%s): recomputing and replacing it",
                    shared, exc.__cause__ or exc)  # fmt: skip
        return None
    if not _matches(surf, key):
        log.warning("shared cache file %s holds another key: recomputing and replacing it", shared)
        return None
    return surf


def _store(surf: ObservableSurface, path: Path | None, shared: Path) -> bool:
    """Put the surface in the shared cache (a copy of ``path`` when given); a failure is a
    warning (the cache only saves time). Returns whether it was stored."""
    try:
        if path is not None:
            _copy_atomic(Path(path), shared)
        else:
            _write_atomic(shared, surf._dump)
    except OSError as exc:
        log.warning("observable surface not stored in the shared cache %s (%s)", shared, exc)
        return False
    return True


def load_or_compute(
    path: Path | None,
    scene: SceneMesh,
    sim_cfg,
    ecfg: EvaluateConfig,
    start: Pose2D | None = None,
    world_cfg=None,
) -> tuple[ObservableSurface, Provenance]:
    """The observable surface: the file ``path`` if its key matches, else the shared cache's
    file of the key (copied to ``path``), else computed, saved to ``path`` and stored in the
    shared cache (``ecfg.cache_folder()``; None: no shared cache).

    A shared cache file that cannot be read, or holds another key, is a warning naming it; the
    surface is then computed and the file replaced. Every file is written to a temporary name
    and renamed, so campaigns computing the same surface at once never leave a half-written
    file. Logs (INFO) where the surface came from, the cache file and the key's hash.

    Args:
        path: the campaign's file (``eval/observable_surface.npz``), or None.
        scene: the true scene.
        sim_cfg: :class:`~scenebot.config.SimConfig` (robot body and camera mount).
        ecfg: evaluation settings (with ``cache_dir``).
        start: start pose; None: as the capture stage picks it.
        world_cfg: :class:`~scenebot.config.WorldConfig`, for its ``start``.

    Returns:
        (surface, where it came from).
    """
    if start is None:
        start = start_pose(scene, world_cfg, collision_map(scene, sim_cfg))
    key = cache_key(scene, sim_cfg, ecfg, start)
    digest = key_hash(key)
    folder = ecfg.cache_folder()
    shared = None if folder is None else cache_file(folder, key)
    if path is not None and Path(path).is_file():
        surf = ObservableSurface.load(path)
        if _matches(surf, key):
            # a campaign's file from before the shared cache (or a lost entry) fills it
            stored = shared is not None and not _is_file(shared) and _store(surf, path, shared)
            log.info("observable surface: %s matches (key %s)%s", path, digest,
                     f"; stored in the shared cache: {shared}" if stored else "")  # fmt: skip
            return surf, Provenance("output", digest, shared)
        log.warning("observable surface %s is stale (scene or settings changed): recomputing", path)
    surf = None if shared is None else _from_cache(shared, key)
    if surf is not None:
        if path is not None:
            try:
                _copy_atomic(shared, Path(path))
            except OSError:  # the cache file went meanwhile (deleted): write what was read
                surf.save(path)
        log.info("observable surface from the shared cache (key %s): %s%s", digest, shared,
                 f", copied to {path}" if path is not None else "")  # fmt: skip
        return surf, Provenance("cache", digest, shared)
    surf = observable_surface(scene, sim_cfg, ecfg, start)
    if path is not None:
        surf.save(path)
    stored = shared is not None and _store(surf, path, shared)
    log.info("observable surface computed (key %s)%s; %s", digest,
             f", saved to {path}" if path is not None else "",
             f"stored in the shared cache: {shared}" if stored
             else "the shared cache is off" if shared is None
             else "not stored in the shared cache")  # fmt: skip
    return surf, Provenance("computed", digest, shared)


def plot_observable(surf: ObservableSurface, png: Path, title: str = "") -> Path:
    """Top-down picture: reachable free space and viewpoints; observable area per column.

    Left: the reachable region (green) over the scene's footprint, the sampled robot
    positions (dots). Right: for each 5 cm column of the scene, the fraction of its surface
    area (walls, furniture, floor, ceiling together) that is observable.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s = surf.summary()
    reach = surf.reachable
    h, w = reach["mask"].shape
    o, res = np.asarray(reach["origin"]), reach["res"]
    ext = [o[0] - res / 2, o[0] + (w - 0.5) * res, o[1] - res / 2, o[1] + (h - 0.5) * res]
    fig, axes = plt.subplots(1, 2, figsize=(13, 5.5), dpi=100)
    ax = axes[0]
    ax.imshow(reach["mask"], origin="lower", extent=ext, cmap="Greens", alpha=0.6, vmin=0, vmax=1.5)
    p = surf.points
    ax.scatter(p[::7, 0], p[::7, 1], s=0.2, c="0.5", alpha=0.25, lw=0)
    ax.plot(surf.positions[:, 0], surf.positions[:, 1], ".", ms=2.5, color="tab:blue")
    ax.set_title(f"reachable free space ({surf.meta.get('reachable_area_m2', float('nan')):.1f} "
                 f"m$^2$) and {len(surf.positions)} viewpoint positions")  # fmt: skip
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax = axes[1]
    bins = [np.arange(ext[0], ext[1] + 0.05, 0.05), np.arange(ext[2], ext[3] + 0.05, 0.05)]
    tot, xe, ye = np.histogram2d(p[:, 0], p[:, 1], bins=bins, weights=surf.weights)
    obs, _, _ = np.histogram2d(
        p[surf.observable, 0], p[surf.observable, 1], bins=bins, weights=surf.observable_weights
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        frac = np.where(tot > 0, obs / tot, np.nan)
    im = ax.imshow(frac.T, origin="lower", extent=[xe[0], xe[-1], ye[0], ye[-1]],
                   cmap="RdYlGn", vmin=0, vmax=1)  # fmt: skip
    fig.colorbar(im, ax=ax, fraction=0.04, label="observable fraction of the column's area")
    ax.set_title(
        f"observable surface: {s['observable_area_m2']:.1f} of {s['total_area_m2']:.1f} m$^2$ "
        f"({100 * s['observable_fraction']:.1f} %)"
    )
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    png = Path(png)
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png)
    plt.close(fig)
    return png
