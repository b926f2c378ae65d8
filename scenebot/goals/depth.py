"""How far a person's shot stands from what it photographs.

A close-up does not register. Of the guided photos of the flat's campaign of 2026-11-28
(c543e0e, rounds 2-3 at 67802d0; 50 photos) whose median depth, the distance along the
optical axis to the surface in view, lay under 0.8 m, 3 of 18 joined the map (close-ups of a
repeating wallpaper, 0.2-0.6 m of it in view: too few motif periods to tell one copy from
another, and the SIFT ratio test rejects the matches between copies), against 13 of 22 from
0.8 to 2 m and 10 of 10 beyond; in the office's guided campaign of 0879029 (75 photos) 0 of
1 under 0.8 m, 20 of 30 from 0.8 to 2 m, 40 of 44 beyond. The map's matchable points do not
see it: a close-up in front of a wall the walk photographed predicts as many as a view
across the room (:mod:`scenebot.score.matchable`).

:func:`view_depths` measures a view's median depth on the round's Poisson mesh (rays on a
coarse grid over the image), and the goals stage asks for no shot nearer than
``goals.person_min_depth_m`` (off by default: the flat's campaign with 0.8 m came out worse,
55.2% against 66.1% at 2 cm, its map less accurate for a reason of its own; the office's
95.1%).
"""

from __future__ import annotations

import numpy as np

from scenebot.geometry import tilted_cam_from_world

GRID = (12, 9)
"""Rays across the image (columns, rows) per view."""


def view_depths(
    poses: np.ndarray, hfov_deg: float, aspect: float, verts: np.ndarray, faces: np.ndarray
) -> np.ndarray:
    """Median depth (m, along the optical axis) of the mesh in each view.

    Args:
        poses: (N, 5) views: x, y, z (m), heading theta (rad), pitch (rad, up positive).
        hfov_deg: horizontal field of view (degrees).
        aspect: image height over width.
        verts: (V, 3) mesh vertices (m).
        faces: (F, 3) triangles.

    Returns:
        (N,) median depth over the rays that hit the mesh; inf for a view that sees none
        of it.
    """
    import open3d as o3d

    poses = np.asarray(poses, np.float64).reshape(-1, 5)
    if not len(poses):
        return np.zeros(0)
    if not len(faces):
        return np.full(len(poses), np.inf)
    tan_h = np.tan(np.radians(hfov_deg) / 2)
    u, v = np.meshgrid(np.linspace(-tan_h, tan_h, GRID[0]),
                       np.linspace(-tan_h * aspect, tan_h * aspect, GRID[1]))  # fmt: skip
    cam = np.stack([u.ravel(), v.ravel(), np.ones(u.size)], 1)  # camera frame, z forward
    Rt = tilted_cam_from_world(poses[:, :3], poses[:, 3], poses[:, 4])
    R = Rt[:, :9].reshape(-1, 3, 3)
    dirs = np.einsum("nji,kj->nki", R, cam)  # world directions (N, K, 3), z-depth 1
    length = np.linalg.norm(dirs, axis=2, keepdims=True)
    origins = np.repeat(poses[:, None, :3], cam.shape[0], axis=1)
    rays = np.concatenate([origins, dirs / length], axis=2).reshape(-1, 6)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(np.asarray(verts, np.float32)),
        o3d.core.Tensor(np.asarray(faces, np.uint32)),
    )
    t = scene.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))["t_hit"].numpy()
    depth = (t.reshape(len(poses), -1) / length[..., 0]).astype(np.float64)  # along the axis
    depth[~np.isfinite(depth)] = np.nan
    out = np.full(len(poses), np.inf)
    seen = np.isfinite(depth).any(axis=1)
    out[seen] = np.nanmedian(depth[seen], axis=1)
    return out
