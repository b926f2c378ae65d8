"""Quality of depth maps and point clouds against true geometry (evaluation only).

The simulator's true geometry is used here to *measure* the dense stage, never to steer it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import cKDTree

if TYPE_CHECKING:  # open3d is imported where it is used: the depth-map metrics need numpy only
    import open3d as o3d

DEFAULT_THRESHOLDS_M = (0.01, 0.02, 0.05)


def depth_map_metrics(
    pred: np.ndarray, true: np.ndarray, rel_tol: float = 0.02
) -> dict[str, float]:
    """Coverage and accuracy of one depth map.

    Args:
        pred: (H, W) estimated z-depth, metres (0 = none).
        true: (H, W) true z-depth, metres (0 = no surface).
        rel_tol: relative error counted as correct.

    Returns:
        ``coverage``: fraction of pixels with a true depth that got a depth;
        ``accuracy``: fraction of those estimates within ``rel_tol`` of the truth;
        ``median_rel_error``: median relative error of the estimates.
    """
    if pred.shape != true.shape:
        raise ValueError(f"depth shapes differ: {pred.shape} vs {true.shape}")
    has_true = true > 0
    has = (pred > 0) & has_true
    rel = np.abs(pred[has] - true[has]) / true[has]
    return {
        "coverage": float(has.sum() / max(has_true.sum(), 1)),
        "accuracy": float(np.mean(rel < rel_tol)) if rel.size else 0.0,
        "median_rel_error": float(np.median(rel)) if rel.size else float("nan"),
    }


def normal_angle_deg(pred: np.ndarray, true: np.ndarray) -> np.ndarray:
    """Angles (degrees) between (..., 3) unit normals where both are non-zero (flattened)."""
    ok = np.any(pred != 0, axis=-1) & np.any(true != 0, axis=-1)
    c = np.sum(pred[ok] * true[ok], axis=-1)
    return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))


def mesh_raycaster(vertices: np.ndarray, triangles: np.ndarray) -> o3d.t.geometry.RaycastingScene:
    """Raycasting scene of a true mesh ((V, 3) metres, (T, 3) indices)."""
    import open3d as o3d

    rc = o3d.t.geometry.RaycastingScene()
    rc.add_triangles(
        o3d.core.Tensor(np.asarray(vertices, np.float32)),
        o3d.core.Tensor(np.asarray(triangles, np.uint32)),
    )
    return rc


def sample_surface(
    vertices: np.ndarray, triangles: np.ndarray, n: int, seed: int = 0
) -> np.ndarray:
    """Area-uniform random points on a triangle mesh.

    Args:
        vertices: (V, 3) vertices, metres.
        triangles: (T, 3) vertex indices.
        n: number of points.
        seed: random seed.

    Returns:
        (n, 3) float64 points, metres.
    """
    rng = np.random.default_rng(seed)
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    tri = rng.choice(len(triangles), size=n, p=area / area.sum())
    r1, r2 = rng.random(n), rng.random(n)
    s1 = np.sqrt(r1)
    return (
        (1 - s1)[:, None] * a[tri] + (s1 * (1 - r2))[:, None] * b[tri] + (s1 * r2)[:, None] * c[tri]
    )


def visible_surface_samples(
    vertices: np.ndarray,
    triangles: np.ndarray,
    cameras: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray, int, int]],
    spacing_m: float = 0.005,
    min_views: int = 2,
    max_samples: int = 2_000_000,
    seed: int = 0,
) -> np.ndarray:
    """Points of the true surface seen by at least ``min_views`` cameras.

    Completeness is measured against this observable surface (as in ETH3D / Tanks and
    Temples): parts no photo sees cannot be reconstructed by any method.

    Args:
        vertices: (V, 3) true mesh vertices, metres.
        triangles: (T, 3) indices.
        cameras: (K (3, 3), R (3, 3), t (3,), width, height) per camera, cam_from_world.
        spacing_m: mean spacing of the samples, metres.
        min_views: views that must see a sample.
        max_samples: cap on the number of area samples drawn.
        seed: random seed.

    Returns:
        (M, 3) float64 visible surface points.
    """
    import open3d as o3d

    v = np.asarray(vertices, np.float64)
    tri = np.asarray(triangles)
    area = 0.5 * np.linalg.norm(
        np.cross(v[tri[:, 1]] - v[tri[:, 0]], v[tri[:, 2]] - v[tri[:, 0]]), axis=1
    )
    n = int(min(max_samples, area.sum() / spacing_m**2))
    pts = sample_surface(v, tri, n, seed)
    rc = mesh_raycaster(v, tri)
    seen = np.zeros(len(pts), np.int32)
    for K, R, t, w, h in cameras:
        pc = pts @ R.T + t
        z = pc[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = (pc @ K.T)[:, :2] / z[:, None]
        inside = (z > 0.05) & (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
        idx = np.flatnonzero(inside)
        if idx.size == 0:
            continue
        c = -R.T @ t
        d = pts[idx] - c
        dist = np.linalg.norm(d, axis=1)
        rays = np.concatenate([np.broadcast_to(c, d.shape), d / dist[:, None]], 1)
        thit = rc.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))["t_hit"].numpy()
        vis = thit > dist - np.maximum(0.003, 1e-3 * dist)
        seen[idx[vis]] += 1
    return pts[seen >= min_views]


def cloud_metrics(
    points: np.ndarray,
    vertices: np.ndarray,
    triangles: np.ndarray,
    reference_samples: np.ndarray,
    thresholds_m: Sequence[float] = DEFAULT_THRESHOLDS_M,
) -> dict[str, dict[str, float]]:
    """Accuracy, completeness and F-score of a point cloud.

    Accuracy at tau: fraction of the cloud's points within tau of the true surface (exact
    point-to-mesh distance). Completeness at tau: fraction of ``reference_samples`` (e.g.
    :func:`visible_surface_samples`) within tau of the cloud. F = 2 A C / (A + C).

    Args:
        points: (N, 3) reconstructed points, metres.
        vertices: (V, 3) true mesh vertices, metres.
        triangles: (T, 3) indices.
        reference_samples: (M, 3) points of the true (observable) surface, metres.
        thresholds_m: distances, metres.

    Returns:
        ``{"1cm": {"accuracy": .., "completeness": .., "fscore": ..}, ...,
        "median_error_m": {"accuracy": .., "completeness": ..}}``.
    """
    import open3d as o3d

    points = np.asarray(points, np.float64)
    if len(points) == 0:
        raise ValueError("cloud_metrics: the point cloud is empty")
    rc = mesh_raycaster(vertices, triangles)
    d_acc = rc.compute_distance(o3d.core.Tensor(points.astype(np.float32))).numpy()
    d_comp, _ = cKDTree(points).query(reference_samples, k=1, workers=-1)
    out: dict[str, dict[str, float]] = {}
    for tau in thresholds_m:
        a = float(np.mean(d_acc < tau))
        c = float(np.mean(d_comp < tau))
        f = 2 * a * c / (a + c) if a + c > 0 else 0.0
        out[f"{round(tau * 100):g}cm"] = {"accuracy": a, "completeness": c, "fscore": f}
    out["median_error_m"] = {
        "accuracy": float(np.median(d_acc)),
        "completeness": float(np.median(d_comp)),
    }
    return out


def true_depth(
    raycaster: o3d.t.geometry.RaycastingScene,
    K: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    width: int,
    height: int,
) -> np.ndarray:
    """True z-depth map of a pinhole camera (COLMAP pixel centres at +0.5).

    Args:
        raycaster: see :func:`mesh_raycaster`.
        K: (3, 3) intrinsics, pixels.
        R: (3, 3) cam_from_world rotation.
        t: (3,) cam_from_world translation, metres.
        width: image width, pixels.
        height: image height, pixels.

    Returns:
        (height, width) float32 z-depth in metres, 0 where no surface is hit.
    """
    import open3d as o3d

    u, v = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    d_cam = np.stack([u, v, np.ones_like(u)], -1).reshape(-1, 3) @ np.linalg.inv(K).T
    d_world = d_cam @ R  # R^T d, with z_cam = 1 so t_hit is the z-depth
    origin = -R.T @ t
    rays = np.concatenate([np.broadcast_to(origin, d_world.shape), d_world], 1)
    thit = raycaster.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))["t_hit"].numpy()
    return np.where(np.isfinite(thit), thit, 0.0).reshape(height, width).astype(np.float32)
