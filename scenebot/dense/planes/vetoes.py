"""Step 6 of the plane fill, in one view: filled pixels emptied again.

A filled pixel behind the depth that all views measured, projected into this view
(``occlusion_min_points`` in its cell), lies behind a surface (a plain object the fill
spread across) and is emptied again (:func:`occluded_fill`). So is a fill that the view's
own SfM points contradict (``sparse_veto``): a close object that stereo missed, whose
features lie in the photo in front of the wall the fill painted there
(:func:`sparse_contradicted_fill`, with the points of :func:`sparse_observations`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def occluded_fill(
    depth: np.ndarray,
    filled: np.ndarray,
    K: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    cloud: np.ndarray,
    *,
    cell_px: int,
    min_points: int,
    rel: float = 0.05,
    margin_m: float = 0.04,
) -> np.ndarray:
    """Filled pixels that lie behind depth measured by the views together.

    A plain object's face whose edges no view measured well is bounded by the plane fill
    of the wall or floor behind it, and a later pass spreads that fill across the object.
    Other views, from elsewhere, often measured the object's texture. The measured cloud
    of all views (thinned) is projected into this view, and a filled pixel with at least
    ``min_points`` measured points in its ``cell_px`` cell nearer than its fill (by ``rel``
    of the depth and ``margin_m``) is behind a measured surface: the fill is wrong there.

    Returns:
        (H, W) bool: the filled pixels to empty again.
    """
    h, w = depth.shape
    out = np.zeros((h, w), bool)
    if not filled.any() or len(cloud) == 0:
        return out
    xc = cloud @ R.T + t
    z = xc[:, 2]
    ok = z > 1e-3
    u = K[0, 0] * xc[ok, 0] / z[ok] + K[0, 2]
    v = K[1, 1] * xc[ok, 1] / z[ok] + K[1, 2]
    z = z[ok]
    ok = (u >= 0) & (u < w) & (v >= 0) & (v < h)
    if not ok.any():
        return out
    near = _nth_nearest_per_cell(u[ok], v[ok], z[ok], (h, w), cell_px, min_points)
    near_px = np.repeat(np.repeat(near, cell_px, 0), cell_px, 1)[:h, :w]
    return filled & (depth * (1 - rel) - margin_m > near_px)


def _nth_nearest_per_cell(
    u: np.ndarray, v: np.ndarray, z: np.ndarray, shape: tuple[int, int], cell_px: int, n: int
) -> np.ndarray:
    """(hc, wc) the ``n``-th nearest depth ``z`` of the points projected at (u, v) into each
    ``cell_px`` cell of an image of ``shape`` (inf where a cell holds fewer)."""
    h, w = shape
    hc, wc = -(-h // cell_px), -(-w // cell_px)
    cell = (v // cell_px).astype(np.int64) * wc + (u // cell_px).astype(np.int64)
    order = np.lexsort((z, cell))
    cell, z = cell[order], z[order]
    first = np.flatnonzero(np.r_[True, cell[1:] != cell[:-1]])
    k = first + n - 1  # the n-th nearest point of each cell
    has = k < np.r_[first[1:], len(cell)]
    near = np.full(hc * wc, np.inf)
    near[cell[first[has]]] = z[k[has]]
    return near.reshape(hc, wc)


def sparse_observations(sparse_dir: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per image name, the SfM points it observes: pixel positions (N, 2) as fractions of
    the image's width and height, and their depths along its optical axis (N,), from the
    dense workspace's undistorted model."""
    import pycolmap

    rec = pycolmap.Reconstruction(str(sparse_dir))
    out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for iid in rec.reg_image_ids():
        im = rec.image(iid)
        obs = [(p.xy, p.point3D_id) for p in im.points2D if p.has_point3D()]
        if not obs:
            out[im.name] = (np.zeros((0, 2)), np.zeros(0))
            continue
        cam = rec.camera(im.camera_id)
        xy = np.array([o[0] for o in obs], np.float64) / [cam.width, cam.height]
        X = np.array([rec.point3D(o[1]).xyz for o in obs], np.float64)
        out[im.name] = (xy, (im.cam_from_world() * X)[:, 2])
    return out


def sparse_contradicted_fill(
    depth: np.ndarray,
    filled: np.ndarray,
    uv: np.ndarray,
    z: np.ndarray,
    *,
    max_edge_px: float,
    rel: float = 0.05,
    margin_m: float = 0.03,
) -> np.ndarray:
    """Filled pixels that the view's own SfM points contradict.

    The SfM points a photo observes are features matched and triangulated across several
    photos: where the photo shows a close object that multi-view stereo missed (a box,
    a bookcase seen from nearby, whose source views did not see it), the plane fill paints
    the wall behind it, yet the object's features lie in the photo, in front of that fill.
    The points are triangulated in the image (Delaunay); each is *contradicted* when it
    lies on a filled pixel, nearer or farther than the fill by more than ``rel`` of the
    depth and ``margin_m``. A triangle whose three corners are contradicted, with no edge
    longer than ``max_edge_px``, covers a surface that is not the filled plane: its filled
    pixels are returned (and the filled pixels within 3 px of a contradicted point).

    Args:
        depth: (H, W) the filled depth map.
        filled: (H, W) bool: which of its pixels the plane fill set.
        uv: (N, 2) pixel positions of the view's SfM observations (x right, y down; pixel
            centres at +0.5, COLMAP's convention).
        z: (N,) their depths.

    Returns:
        (H, W) bool: the filled pixels to empty again.
    """
    import cv2

    h, w = depth.shape
    out = np.zeros((h, w), np.uint8)
    if not filled.any() or len(z) == 0:
        return out.astype(bool)
    u = np.clip(uv[:, 0].astype(np.int64), 0, w - 1)
    v = np.clip(uv[:, 1].astype(np.int64), 0, h - 1)
    d = depth[v, u]
    bad = filled[v, u] & (d > 0) & (np.abs(z - d) > rel * d + margin_m)
    for k in np.flatnonzero(bad):  # the point's own neighbourhood
        cv2.circle(out, (int(uv[k, 0]), int(uv[k, 1])), 3, 1, -1)
    if bad.sum() >= 3:
        _paint_contradicted_triangles(out, uv, bad, max_edge_px)
    return out.astype(bool) & filled


def _paint_contradicted_triangles(
    out: np.ndarray, uv: np.ndarray, bad: np.ndarray, max_edge_px: float
) -> None:
    """Paint into ``out`` (in place) the Delaunay triangles of the points ``uv`` whose three
    corners are ``bad``, with no edge longer than ``max_edge_px``."""
    import cv2
    from scipy.spatial import Delaunay, QhullError

    try:
        tri = Delaunay(uv).simplices
    except QhullError:  # degenerate (collinear) points
        tri = np.zeros((0, 3), np.int64)
    corners = uv[tri[bad[tri].all(1)]]
    edge = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(1, initial=0.0)
    for c in corners[edge <= max_edge_px]:
        cv2.fillConvexPoly(out, np.round(c - 0.5).astype(np.int32), 1)
