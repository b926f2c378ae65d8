"""How many photos saw each part of the map's surface: the coverage picture of a person's
advice (``robot: photos``), where surface seen by fewer than two photos cannot be
reconstructed (a point needs two views) and is where the next shots are needed.

A mesh vertex is seen by a photo when it projects inside the image, in front of the camera,
and the ray from the camera centre to it meets no other part of the mesh first (open3d ray
casting, a tolerance of a few hundredths of the camera's distance: the Poisson surface is
smooth, not exact).
"""

from __future__ import annotations

import numpy as np

from scenebot.geometry import SparseMap


def photo_counts(
    verts: np.ndarray,
    faces: np.ndarray,
    smap: SparseMap,
    max_vertices: int,
    rng: np.random.Generator,
    tolerance: float = 0.03,
) -> tuple[np.ndarray, np.ndarray]:
    """Photos seeing each of (at most ``max_vertices``, a seeded sample of) the mesh vertices.

    Args:
        verts: (V, 3) mesh vertices (m).
        faces: (F, 3) triangles.
        smap: the map (its registered photos' poses and intrinsics).
        max_vertices: sample size (the picture needs no more).
        rng: random generator for the sample.
        tolerance: occlusion tolerance, a fraction of the distance to the camera.

    Returns:
        (K, 3) the vertices sampled (m), and (K,) int photos seeing each.
    """
    import open3d as o3d

    keep = np.arange(len(verts))
    if len(keep) > max_vertices:
        keep = np.sort(rng.choice(len(verts), size=max_vertices, replace=False))
    pts = np.asarray(verts[keep], np.float64)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(np.asarray(verts, np.float32)),
        o3d.core.Tensor(np.asarray(faces, np.uint32)),
    )
    counts = np.zeros(len(pts), np.int64)
    for R, t, K in zip(smap.R, smap.t, smap.intrinsics, strict=True):
        q = pts @ R.T + t
        z = np.maximum(q[:, 2], 1e-9)
        u, v = K.fx * q[:, 0] / z + K.cx, K.fy * q[:, 1] / z + K.cy
        inside = (q[:, 2] > 0) & (u >= 0) & (v >= 0) & (u < K.width) & (v < K.height)
        if not inside.any():
            continue
        C = -R.T @ t
        d = pts[inside] - C
        dist = np.linalg.norm(d, axis=1)
        rays = np.concatenate([np.broadcast_to(C, d.shape), d / dist[:, None]], axis=1)
        hit = scene.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))["t_hit"].numpy()
        counts[np.flatnonzero(inside)] += hit >= dist * (1 - tolerance)
    return pts, counts
