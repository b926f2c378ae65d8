"""Step 1 of the plane fill: the planes of the measured depth.

Every view's measured depth is back-projected and thinned to a voxel grid with its stereo
normals (:func:`thinned_cloud`); planes are peeled off the cloud by oriented RANSAC, largest
first (:func:`detect_planes`), and made exactly upright or level when they are nearly so.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from scenebot.dense.config import PlaneFillConfig
from scenebot.dense.planes.geometry import Plane, backproject_pixels, plane_extent

#: a plane within this angle (degrees) of the map's horizontal may be the floor
LEVEL_DEG = 10.0


def thinned_cloud(
    views: Iterable[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]],
    rng: np.random.Generator,
    *,
    points_per_view: int,
    voxel_m: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The measured points of the views with their world normals, thinned to one point
    per voxel.

    Args:
        views: ``(depth, normal, K, R, t)`` per view: its measured maps and camera.
        rng: draws at most ``points_per_view`` of each view's points.
        points_per_view: the most points drawn per view.
        voxel_m: voxel size (m).

    Returns:
        (N, 3) points and (N, 3) unit normals.
    """
    pts, nrms = [], []
    for d, nm, K, R, t in views:
        v, u = np.nonzero((d > 0) & (np.linalg.norm(nm, axis=-1) > 0.5))
        X, N = backproject_pixels(d[v, u], v, u, K, R, t), nm[v, u].astype(np.float64) @ R
        if len(X) > points_per_view:
            pick = rng.choice(len(X), points_per_view, replace=False)
            X, N = X[pick], N[pick]
        pts.append(X)
        nrms.append(N / np.linalg.norm(N, axis=1, keepdims=True))
    cloud = np.concatenate(pts) if pts else np.zeros((0, 3))
    cloud_n = np.concatenate(nrms) if nrms else np.zeros((0, 3))
    if len(cloud):
        first = _first_per_voxel(np.floor(cloud / voxel_m).astype(np.int64))
        cloud, cloud_n = cloud[first], cloud_n[first]
    return cloud, cloud_n


def _first_per_voxel(keys: np.ndarray) -> np.ndarray:
    """The index of each voxel's first point, voxels in lexicographic order of their (N, 3)
    integer ``keys``: ``np.unique(keys, axis=0, return_index=True)[1]``, from one integer
    per voxel (several times faster) where the grid's cells fit in 62 bits."""
    lo = keys.min(0)
    span = keys.max(0) - lo + 1
    if float(np.prod(span.astype(np.float64))) >= 2.0**62:
        return np.unique(keys, axis=0, return_index=True)[1]
    k = keys - lo
    flat = (k[:, 0] * span[1] + k[:, 1]) * span[2] + k[:, 2]  # lexicographic order kept
    return np.unique(flat, return_index=True)[1]


#: Tukey's biweight constant (95% efficiency at the normal distribution)
TUKEY_C = 4.685


def _fit_plane(x: np.ndarray, iterations: int = 10) -> tuple[np.ndarray, float]:
    """Robust plane through points: unit normal and offset.

    Least squares, then iteratively reweighted with Tukey's biweight on the residuals
    (scale: their median absolute deviation). A plain least-squares fit over a RANSAC band
    is pulled by what the band also holds (a baseboard's foot, a rug's edge, a table leg):
    the office's floor came out 0.2 deg tilted from 45,000 points whose robust fit is level
    within 0.02 deg, and the tilt, handed to every plane as the room's up, put its ceiling
    1-3 cm off across the room.
    """
    w = np.ones(len(x))
    n, d = np.array([0.0, 0.0, 1.0]), 0.0
    for k in range(iterations + 1):
        c = (w[:, None] * x).sum(0) / w.sum()
        y = (x - c) * np.sqrt(w)[:, None]
        n = np.linalg.svd(y, full_matrices=False)[2][-1]
        d = float(-n @ c)
        if k == iterations or len(x) < 4:
            break
        r = x @ n + d
        scale = 1.4826 * float(np.median(np.abs(r - np.median(r))))
        if scale <= 1e-12:
            break
        w = np.clip(1.0 - (r / (TUKEY_C * scale)) ** 2, 0.0, None) ** 2
        if w.sum() < 3:
            break
    return n, d


def _ransac_point_normal(
    pts: np.ndarray,
    nrm: np.ndarray,
    distance_m: float,
    cos_normal: float,
    rng: np.random.Generator,
    hypotheses: int = 512,
    score_points: int = 20000,
) -> tuple[np.ndarray, float, np.ndarray]:
    """The plane through one point along its normal that most other points agree with.

    A point agrees when it lies within ``distance_m`` of the plane and its own normal is
    within ``arccos(cos_normal)`` of the plane's. Hypotheses come from single oriented
    points (Schnabel et al.'s oriented RANSAC); the best is refitted robustly twice
    (:func:`_fit_plane`).

    Returns:
        The unit normal, offset and the (N,) inlier mask over ``pts``.
    """
    n_pts = len(pts)
    hyp = rng.choice(n_pts, min(hypotheses, n_pts), replace=False)
    sub = rng.choice(n_pts, min(score_points, n_pts), replace=False)
    hn = nrm[hyp]
    hd = -np.einsum("ij,ij->i", hn, pts[hyp])
    agree = (np.abs(pts[sub] @ hn.T + hd) < distance_m) & (np.abs(nrm[sub] @ hn.T) > cos_normal)
    best = int(agree.sum(0).argmax())
    n, d = hn[best], float(hd[best])
    on = np.zeros(n_pts, bool)
    for _ in range(2):
        on = (np.abs(pts @ n + d) < distance_m) & (np.abs(nrm @ n) > cos_normal)
        if on.sum() < 3:
            break
        n, d = _fit_plane(pts[on])
    on = (np.abs(pts @ n + d) < distance_m) & (np.abs(nrm @ n) > cos_normal)
    return n, d, on


def _segment_plane(rest: np.ndarray, distance_m: float, min_size: float):
    """open3d's ``segment_plane`` on positions alone, refitted robustly (:func:`_fit_plane`): unit
    normal, offset and the (N,) inlier mask; None when its plane holds fewer than
    ``min_size`` points."""
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(rest))
    _, idx = pcd.segment_plane(distance_m, 3, 500)
    if len(idx) < min_size:
        return None
    n, d = _fit_plane(rest[idx])
    on = np.abs(rest @ n + d) < distance_m
    if on.sum() < 3:
        on[idx] = True
    return n, d, on


def _peel_planes(
    points: np.ndarray,
    normals: np.ndarray | None,
    rng: np.random.Generator,
    *,
    distance_m: float,
    min_share: float,
    max_planes: int,
    merge_angle_deg: float,
    normal_deg: float,
) -> tuple[list[list[np.ndarray]], list[tuple[np.ndarray, float]]]:
    """RANSAC's planes, largest first, each merged into an earlier one within
    ``merge_angle_deg`` and ``2 * distance_m`` (see :func:`detect_planes`).

    Returns:
        Per plane its inlier sets (one per RANSAC round merged into it) and its (normal,
        offset).
    """
    rest = np.asarray(points, np.float64)
    rest_n = None if normals is None else np.asarray(normals, np.float64)
    cos_normal = np.cos(np.radians(normal_deg))
    n_all = len(rest)
    found: list[list[np.ndarray]] = []  # inlier sets
    fits: list[tuple[np.ndarray, float]] = []
    cos_merge = np.cos(np.radians(merge_angle_deg))
    for _ in range(4 * max_planes):
        if len(fits) >= max_planes or len(rest) < max(3, min_share * n_all):
            break
        if rest_n is None:
            plane = _segment_plane(rest, distance_m, max(3, min_share * n_all))
            if plane is None:
                break
            n, d, on = plane
        else:
            n, d, on = _ransac_point_normal(rest, rest_n, distance_m, cos_normal, rng)
            if on.sum() < max(3, min_share * n_all):
                break
        inl = rest[on]
        c = inl.mean(0)
        for k, (nk, dk) in enumerate(fits):
            if abs(n @ nk) > cos_merge and abs(c @ nk + dk) < 2 * distance_m:
                found[k].append(inl)
                fits[k] = _fit_plane(np.concatenate(found[k]))
                break
        else:
            found.append([inl])
            fits.append((n, d))
        rest = rest[~on]
        if rest_n is not None:
            rest_n = rest_n[~on]
    return found, fits


def _with_extent(
    n: np.ndarray, d: float, inl: np.ndarray, cell_m: float, min_cell_points: int,
    close_cells: int,
) -> Plane | None:  # fmt: skip
    """The plane (n, d) with in-plane axes, its inliers' centroid as origin and their
    extent raster (:func:`plane_extent`); None when the extent holds no cell."""
    origin = inl.mean(0)
    e1 = np.cross(n, [0.0, 0.0, 1.0] if abs(n[2]) < 0.9 else [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    basis = np.stack([e1, np.cross(n, e1)])
    lo, occ = plane_extent((inl - origin) @ basis.T, cell_m, min_cell_points, close_cells)
    if not occ.any():
        return None
    return Plane(n, d, basis, origin, cell_m, lo, occ, len(inl))


def detect_planes(
    points: np.ndarray,
    *,
    distance_m: float,
    min_share: float,
    max_planes: int,
    seed: int,
    cell_m: float,
    min_cell_points: int,
    close_cells: int,
    merge_angle_deg: float,
    normals: np.ndarray | None = None,
    normal_deg: float,
    snap_deg: float,
) -> list[Plane]:
    """Peel planes off a cloud by RANSAC, largest first.

    Without ``normals``, open3d's ``segment_plane`` proposes each plane; with them (the
    stereo's per-pixel normals), oriented RANSAC (:func:`_ransac_point_normal`) does, and a
    point belongs to a plane only where its normal agrees within ``normal_deg``: a phantom
    plane that cuts across several surfaces (a diagonal through box corners, a slice beneath
    the floor) finds no support. Each plane is refitted robustly to its inliers (and
    takes the points within ``distance_m`` of the refit); a plane within
    ``merge_angle_deg`` and ``2 * distance_m`` of one already found (a noisy floor peeled in
    slices) is merged into it.

    Args:
        points: (N, 3) points (m).
        distance_m: inlier distance of RANSAC.
        min_share: stop when the next plane holds fewer than this share of ``points``.
        max_planes: at most this many planes.
        seed: RANSAC seed.
        cell_m, min_cell_points, close_cells: the extent raster (:func:`plane_extent`).
        merge_angle_deg: planes closer in angle (and offset) are one.
        normals: (N, 3) unit normals of the points, or None.
        normal_deg: largest angle between a point's normal and its plane's.
        snap_deg: planes within this angle (degrees) of horizontal or vertical are made
            exactly so (:func:`_snap_plane`); 0: as fitted.

    Returns:
        The planes with their extents, largest first.
    """
    import open3d as o3d

    o3d.utility.random.seed(seed)
    rng = np.random.default_rng(seed)
    found, fits = _peel_planes(
        points, normals, rng, distance_m=distance_m, min_share=min_share,
        max_planes=max_planes, merge_angle_deg=merge_angle_deg, normal_deg=normal_deg,
    )  # fmt: skip
    up = _up_direction(found, fits, np.cos(np.radians(LEVEL_DEG))) if snap_deg else None
    fitted = []
    for sets, (n, d) in zip(found, fits, strict=True):
        inl = np.concatenate(sets)
        if up is not None:
            n, d = _snap_plane(n, d, inl, up, snap_deg)
        d = _recentre(n, d, points, normals, np.cos(np.radians(normal_deg)), distance_m)
        fitted.append((n, d, inl))
    planes: list[Plane] = []
    for n, d, inl in _merge_recentred(fitted, np.cos(np.radians(merge_angle_deg)), distance_m):
        plane = _with_extent(n, d, inl, cell_m, min_cell_points, close_cells)
        if plane is not None:
            planes.append(plane)
    planes.sort(key=lambda p: -p.inliers)
    return planes


#: :func:`_recentre`'s window, in RANSAC distances either side of the plane: the span within
#: which :func:`_peel_planes` merges a plane into an earlier one
RECENTRE_BAND = 2.0


def _recentre(
    n: np.ndarray, d: float, points: np.ndarray, normals: np.ndarray | None, cos_normal: float,
    distance_m: float, iterations: int = 10,
) -> float:  # fmt: skip
    """The offset of the plane (n, d) moved to the centre of its surface's points: the
    median signed distance of the points (whose normals agree, with ``normals``) within
    :data:`RECENTRE_BAND` RANSAC distances of it, the window moved with it until it rests
    (a surface farther away than that stays a plane of its own).

    Measured depth spreads a plain wall's points over several RANSAC distances (its
    stereo noise grows with the distance; at 3 m a few centimetres either way), and the
    slab RANSAC keeps (``distance_m`` either side) may lie anywhere in that spread: an office
    wall was found 2 cm off, its other half 4 cm away as a second plane (too far to merge),
    and the views' vote kept the wrong one. The median over a window two slabs wide walks
    to the middle of the spread (the voxel grid's rows, a voxel apart, even out in it), and
    both halves of one wall arrive at the same offset (:func:`_merge_recentred`)."""
    proj = np.asarray(points, np.float64) @ n
    if normals is not None:
        proj = proj[np.abs(np.asarray(normals) @ n) > cos_normal]
    band = RECENTRE_BAND * distance_m
    for _ in range(iterations):
        near = np.abs(proj + d) < band
        if near.sum() < 3:
            break
        moved = -float(np.median(proj[near]))
        if abs(moved - d) < 1e-4 * distance_m:
            return moved
        d = moved
    return d


def _merge_recentred(
    fitted: list[tuple[np.ndarray, float, np.ndarray]], cos_merge: float, distance_m: float
) -> list[tuple[np.ndarray, float, np.ndarray]]:
    """The recentred planes (normal, offset, inliers), those parallel within the merge
    angle whose offsets now lie within ``distance_m`` of each other merged into the larger
    one (the inliers of both, the larger's normal and offset)."""
    order = sorted(range(len(fitted)), key=lambda k: -len(fitted[k][2]))
    out: list[list] = []
    for k in order:
        n, d, inl = fitted[k]
        for m in out:
            s = float(n @ m[0])
            if abs(s) > cos_merge and abs(d * np.sign(s) - m[1]) < distance_m:
                m[2] = np.concatenate([m[2], inl])
                break
        else:
            out.append([n, d, inl])
    return [(n, d, inl) for n, d, inl in out]


def detect_settings(cfg: PlaneFillConfig) -> dict:
    """The settings of :func:`detect_planes` (all but ``normals``) from the config.

    With ``normal_deg: null`` the planes are found by position alone (pass no ``normals``);
    the angle is then unused.
    """
    return {
        "distance_m": cfg.ransac_distance_m,
        "min_share": cfg.min_plane_share,
        "max_planes": cfg.max_planes,
        "seed": cfg.seed,
        "cell_m": cfg.extent_cell_m,
        "min_cell_points": cfg.extent_min_points,
        "close_cells": cfg.extent_close_cells,
        "merge_angle_deg": cfg.merge_angle_deg,
        "normal_deg": cfg.normal_deg or 90.0,
        "snap_deg": cfg.snap_deg,
    }


def _up_direction(
    found: list[list[np.ndarray]], fits: list[tuple[np.ndarray, float]], cos_max: float
) -> np.ndarray | None:
    """The normal of the largest plane within ``arccos(cos_max)`` of the map's z axis (the
    floor of a room), signed upwards; None when there is none."""
    best, up = 0, None
    for sets, (n, _) in zip(found, fits, strict=True):
        size = sum(len(s) for s in sets)
        if abs(n[2]) > cos_max and size > best:
            best, up = size, n * np.sign(n[2])
    return up


def _snap_plane(
    n: np.ndarray, d: float, inliers: np.ndarray, up: np.ndarray, snap_deg: float
) -> tuple[np.ndarray, float]:
    """A plane within ``snap_deg`` of horizontal (normal along ``up``) or of vertical
    (normal perpendicular to it) made exactly so, its offset the median over its inliers.

    Walls stand upright and floors lie flat: a wall fitted 1 degree off over its few
    measured patches is 4 cm off at the top of a 2.6 m wall, which its plane completion
    then repeats over the whole wall.
    """
    s = float(n @ up)
    if abs(s) > np.cos(np.radians(snap_deg)):
        n = up * np.sign(s)
    elif abs(s) < np.sin(np.radians(snap_deg)):
        n = n - s * up
        n = n / np.linalg.norm(n)
    else:
        return n, d
    return n, float(-np.median(inliers @ n))
