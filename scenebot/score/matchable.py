"""Which candidate views could be registered to the map: the map points they would match.

A photo joins the map (SfM registration, visual localization) through SIFT matches to the
map's 3D points, and SIFT matches a point across a limited change of viewpoint: roughly 45
degrees of viewing direction and a factor of 2 in distance (scale). A goal whose view shows
photographed but plain surface (a white wall at a grazing angle, the wall beside a box) passes
an overlap test by area, ``goals.min_seen_fraction``, yet its photos match nothing and are
lost. In the office campaign of 2026-11-26, 8 of its 20 goals (39 photos) never registered;
their views held 1-39 map points seen within 45 degrees and a factor 2 of distance (one held
712), against 278-3781 for the goals whose photos all registered.

:func:`matchable_points` counts, per candidate view, the map points that project inside the
image in front of the camera and that the candidate sees from within ``max_angle_deg`` of the
mean direction the map's cameras saw them from, at a distance within a factor
``max_scale_ratio`` of the map cameras' mean distance.

Occlusion is not tested: the Poisson mesh is too smooth to judge it. Measured: a goal beside a
box had the mesh at 0.35 m over its whole lower image while its photos saw the room behind
(all five registered), and a test against the mesh's depth kept 36 of its 2383 points. So a
point behind a wall counts; the count is an upper bound that rejects the views with nothing to
match, which is what loses photos.
"""

from __future__ import annotations

import numpy as np


def matchable_points(
    views: np.ndarray,
    width: int,
    height: int,
    xyz: np.ndarray,
    view_dir: np.ndarray,
    view_dist: np.ndarray,
    max_angle_deg: float,
    max_scale_ratio: float,
    near_m: float,
) -> np.ndarray:
    """Map points each view sees close enough to how the map saw them to match them.

    Args:
        views: (N, 19) packed views (:mod:`scenebot.score.geometry`).
        width: image width of the views' intrinsics (pixels).
        height: image height (pixels).
        xyz: (P, 3) map points (m).
        view_dir: (P, 3) unit mean direction from each point towards its observing cameras.
        view_dist: (P,) mean distance from each point to its observing cameras (m).
        max_angle_deg: largest angle between the direction towards the view and
            ``view_dir`` (degrees; ``score.match_angle_deg``).
        max_scale_ratio: largest ratio of the view's distance to ``view_dist``, either way
            (``score.match_scale_ratio``).
        near_m: points nearer than this along the optical axis are not seen (m;
            ``score.near_m``).

    Returns:
        (N,) int64 count per view.
    """
    views = np.asarray(views, dtype=np.float64).reshape(-1, 19)
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    view_dir = np.asarray(view_dir, dtype=np.float64).reshape(-1, 3)
    out = np.zeros(len(views), dtype=np.int64)
    if len(xyz) == 0:
        return out
    cos_max = np.cos(np.deg2rad(max_angle_deg))
    log_ratio = np.log(max(max_scale_ratio, 1.0))
    log_dist = np.log(np.maximum(np.asarray(view_dist, dtype=np.float64), 1e-6))
    for i, v in enumerate(views):
        R, t, C = v[:9].reshape(3, 3), v[9:12], v[12:15]
        to_cam = C - xyz
        dist = np.maximum(np.linalg.norm(to_cam, axis=1), 1e-6)
        ok = np.einsum("ij,ij->i", to_cam, view_dir) >= cos_max * dist
        ok &= np.abs(np.log(dist) - log_dist) <= log_ratio
        X = xyz[ok] @ R.T + t
        X = X[X[:, 2] > near_m]
        u = v[15] * X[:, 0] / X[:, 2] + v[17]
        r = v[16] * X[:, 1] / X[:, 2] + v[18]
        out[i] = int(((u >= 0) & (u < width) & (r >= 0) & (r < height)).sum())
    return out
