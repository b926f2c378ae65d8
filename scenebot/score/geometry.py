"""Camera geometry of the taichi scorer and its numpy reference: packed views, the map's
points and source cameras.

Conventions as in :mod:`scenebot.geometry` (where :class:`Intrinsics` and
:func:`planar_cam_from_world` live): world frame in metres, z up, the camera plane is z = 0;
camera axes as in OpenCV/COLMAP (x right, y down, z forward); poses are ``cam_from_world``.

A set of pinhole views is packed as an ``(N, 19)`` float array, one row per view:
``R`` row-major (9), ``t`` (3), camera centre ``C = -R^T t`` (3), ``fx, fy, cx, cy`` (4, pixels).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scenebot.geometry import Intrinsics, planar_cam_from_world

VIEW_COLS = 19
"""Columns of a packed view array."""


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


def candidate_views(poses: np.ndarray, intr: Intrinsics) -> np.ndarray:
    """Packed views of planar candidate poses.

    Args:
        poses: (N, 3) candidate poses (x m, y m, theta rad).
        intr: virtual camera intrinsics.

    Returns:
        (N, 19) float64 packed views.
    """
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    Rt = planar_cam_from_world(poses[:, 0], poses[:, 1], poses[:, 2])
    return pack_views(Rt[:, :9].reshape(-1, 3, 3), Rt[:, 9:], intr)


@dataclass(frozen=True)
class SparseMap:
    """What the score stages read from a COLMAP model.

    Attributes:
        xyz: (P, 3) 3D point positions (m).
        track_len: (P,) number of images observing each point.
        view_dir: (P, 3) unit mean direction from each point towards the cameras observing it.
        view_dist: (P,) mean distance from each point to the cameras observing it (m).
        R: (S, 3, 3) cam_from_world rotations of the registered images.
        t: (S, 3) cam_from_world translations (m).
        intrinsics: (S,) pinhole approximation of each image's camera.
        names: (S,) image names.
    """

    xyz: np.ndarray
    track_len: np.ndarray
    view_dir: np.ndarray
    view_dist: np.ndarray
    R: np.ndarray
    t: np.ndarray
    intrinsics: list[Intrinsics]
    names: list[str]

    @property
    def centres(self) -> np.ndarray:
        """(S, 3) camera centres (m)."""
        return -np.einsum("nji,nj->ni", self.R, self.t)


def _pinhole(cam) -> Intrinsics:
    """Pinhole approximation (distortion ignored) of a pycolmap camera."""
    p = np.asarray(cam.params, dtype=np.float64)
    model = cam.model.name if hasattr(cam.model, "name") else str(cam.model)
    if model in ("SIMPLE_PINHOLE", "SIMPLE_RADIAL", "RADIAL", "SIMPLE_RADIAL_FISHEYE"):
        fx = fy = p[0]
        cx, cy = p[1], p[2]
    else:  # PINHOLE, OPENCV, FULL_OPENCV, ... start with fx, fy, cx, cy
        fx, fy, cx, cy = p[:4]
    return Intrinsics(int(cam.width), int(cam.height), float(fx), float(fy), float(cx), float(cy))


def read_sparse_map(sfm_dir: str | Path) -> SparseMap:
    """Read registered images and 3D points of a COLMAP model.

    Args:
        sfm_dir: folder with cameras.bin, images.bin, points3D.bin (robot frame, z up, m).

    Returns:
        The map's points and source cameras.

    Raises:
        FileNotFoundError: the folder holds no COLMAP model.
    """
    import pycolmap

    sfm_dir = Path(sfm_dir)
    if not (sfm_dir / "images.bin").exists() and not (sfm_dir / "images.txt").exists():
        raise FileNotFoundError(
            f"{sfm_dir}: no COLMAP model (images.bin) here; run the sfm stage for this round first"
        )
    rec = pycolmap.Reconstruction(str(sfm_dir))
    Rs, ts, intrs, names, centres = [], [], [], [], {}
    for image_id in sorted(rec.images):
        im = rec.images[image_id]
        if not im.has_pose:
            continue
        pose = im.cam_from_world() if callable(im.cam_from_world) else im.cam_from_world
        R = np.asarray(pose.rotation.matrix(), dtype=np.float64)
        t = np.asarray(pose.translation, dtype=np.float64)
        Rs.append(R)
        ts.append(t)
        intrs.append(_pinhole(rec.cameras[im.camera_id]))
        names.append(im.name)
        centres[image_id] = -R.T @ t
    xyz, tl, vd, vdist = [], [], [], []
    for _pid, pt in rec.points3D.items():
        p = np.asarray(pt.xyz, dtype=np.float64)
        ids = [el.image_id for el in pt.track.elements if el.image_id in centres]
        if not ids:
            continue
        d = np.array([centres[i] - p for i in ids])
        dn = np.linalg.norm(d, axis=1, keepdims=True)
        d /= dn + 1e-12
        m = d.mean(axis=0)
        xyz.append(p)
        tl.append(len(ids))
        vd.append(m / (np.linalg.norm(m) + 1e-12))
        vdist.append(float(dn.mean()))
    return SparseMap(
        xyz=np.array(xyz, dtype=np.float64).reshape(-1, 3),
        track_len=np.array(tl, dtype=np.int64),
        view_dir=np.array(vd, dtype=np.float64).reshape(-1, 3),
        view_dist=np.array(vdist, dtype=np.float64),
        R=np.array(Rs, dtype=np.float64).reshape(-1, 3, 3),
        t=np.array(ts, dtype=np.float64).reshape(-1, 3),
        intrinsics=intrs,
        names=names,
    )
