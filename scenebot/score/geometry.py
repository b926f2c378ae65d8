"""Camera geometry of the taichi scorer and its numpy reference: packed views, the map's
points and source cameras.

Conventions as in :mod:`scenebot.geometry` (where :class:`Intrinsics` and
:func:`planar_cam_from_world` live): world frame in metres, z up, the camera plane is z = 0;
camera axes as in OpenCV/COLMAP (x right, y down, z forward); poses are ``cam_from_world``.

A set of pinhole views is packed as an ``(N, 19)`` float array, one row per view:
``R`` row-major (9), ``t`` (3), camera centre ``C = -R^T t`` (3), ``fx, fy, cx, cy`` (4, pixels).
"""

from __future__ import annotations

import numpy as np

from scenebot.geometry import Intrinsics, tilted_cam_from_world

VIEW_COLS = 19


def pack_views(R: np.ndarray, t: np.ndarray, intr: Intrinsics | list[Intrinsics]) -> np.ndarray:
    """Pack poses and intrinsics into the ``(N, 19)`` view layout.

    Args:
        R: (N, 3, 3) cam_from_world rotations.
        t: (N, 3) cam_from_world translations (m).
        intr: one intrinsics for all views, or one per view (all of the same image size).

    Returns:
        (N, 19) float64 packed views.
    """
    R = np.asarray(R, dtype=np.float64).reshape(-1, 3, 3)
    t = np.asarray(t, dtype=np.float64).reshape(-1, 3)
    n = R.shape[0]
    intrs = intr if isinstance(intr, list) else [intr] * n
    if len(intrs) != n:
        raise ValueError(f"pack_views: {n} poses but {len(intrs)} intrinsics")
    K = np.array([[k.fx, k.fy, k.cx, k.cy] for k in intrs], dtype=np.float64).reshape(n, 4)
    C = -np.einsum("nji,nj->ni", R, t)
    return np.concatenate([R.reshape(n, 9), t, C, K], axis=1)


def candidate_views(poses: np.ndarray, intr: Intrinsics, pitch: float = 0.0) -> np.ndarray:
    """Packed views of planar candidate poses: a robot's camera in the camera plane (z = 0),
    tilted up by its mount's ``pitch`` (rad; :func:`~scenebot.geometry.mount_pitch`).

    Args:
        poses: (N, 3) candidate poses (x m, y m, theta rad).
        intr: virtual camera intrinsics.
        pitch: the camera's tilt on the robot (rad, up positive).

    Returns:
        (N, 19) float64 packed views.
    """
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    xyz = np.column_stack([poses[:, :2], np.zeros(len(poses))])
    Rt = tilted_cam_from_world(xyz, poses[:, 2], np.full(len(poses), pitch))
    return pack_views(Rt[:, :9].reshape(-1, 3, 3), Rt[:, 9:], intr)


def person_views(poses: np.ndarray, intr: Intrinsics) -> np.ndarray:
    """Packed views of a person's candidate poses (six degrees of freedom, roll 0).

    Args:
        poses: (N, 5) candidate poses (x, y, z m, theta rad, pitch rad up positive).
        intr: virtual camera intrinsics.

    Returns:
        (N, 19) float64 packed views.
    """
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 5)
    Rt = tilted_cam_from_world(p[:, :3], p[:, 3], p[:, 4])
    return pack_views(Rt[:, :9].reshape(-1, 3, 3), Rt[:, 9:], intr)
