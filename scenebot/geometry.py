"""Camera geometry shared by the simulator and every stage: intrinsics, camera rotations,
camera poses of a map, the camera mount.

Conventions (the simulator's renderer, the score stage's views and COLMAP alike): world frame
in metres, z up, the robot's camera plane is z = 0 in a map; camera axes as in OpenCV/COLMAP
(x right, y down, z forward); a pose is ``cam_from_world`` (R, t), a world point X maps to
``R @ X + t`` in camera coordinates, the centre is ``C = -R^T t``; pixel (i, j) (row, column)
has its centre at image coordinates (j + 0.5, i + 0.5) (COLMAP's convention), so the
principal point of an ideal camera is (width / 2, height / 2).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics (pixels).

    Attributes:
        width: image width (pixels).
        height: image height (pixels).
        fx: focal length along x (pixels).
        fy: focal length along y (pixels).
        cx: principal point x (pixels, image coordinates with pixel centres at +0.5).
        cy: principal point y (pixels).
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    @staticmethod
    def from_hfov(width: int, height: int, hfov_deg: float) -> Intrinsics:
        """Square-pixel intrinsics with a horizontal field of view (degrees), principal point
        at the image centre."""
        f = 0.5 * width / np.tan(np.deg2rad(hfov_deg) / 2)
        return Intrinsics(width, height, f, f, width / 2, height / 2)

    @property
    def K(self) -> np.ndarray:
        """(3, 3) calibration matrix."""
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1.0]])

    def scaled(self, width: int, height: int | None = None) -> Intrinsics:
        """The same field of view at another resolution.

        Args:
            width: new width (pixels).
            height: new height (pixels); default keeps the aspect ratio.

        Returns:
            The rescaled intrinsics.
        """
        sx = width / self.width
        if height is None:
            height = max(1, round(self.height * sx))
        sy = height / self.height
        return Intrinsics(width, height, self.fx * sx, self.fy * sy, self.cx * sx, self.cy * sy)


def look_rotation(heading_rad: float, pitch_rad: float = 0.0) -> np.ndarray:
    """cam_from_world rotation of a camera looking along ``heading_rad`` (counter-clockwise
    from world +x), tilted up by ``pitch_rad``, with no roll.

    Returns:
        (3, 3) rotation whose rows are the camera's x (right), y (down), z (forward) axes.
    """
    ch, sh = np.cos(heading_rad), np.sin(heading_rad)
    cp, sp = np.cos(pitch_rad), np.sin(pitch_rad)
    fwd = np.array([cp * ch, cp * sh, sp])
    right = np.array([sh, -ch, 0.0])
    down = np.cross(fwd, right)
    return np.stack([right, down, fwd])


def orientation_rotation(heading_rad: float, pitch_rad: float, roll_rad: float) -> np.ndarray:
    """cam_from_world rotation of a camera looking along ``heading_rad`` (counter-clockwise
    from world +x), tilted up by ``pitch_rad`` and rolled by ``roll_rad`` about its optical
    axis: how a phone's orientation sensors (compass and accelerometer) describe it.

    Returns:
        (3, 3) rotation whose rows are the camera's x (right), y (down), z (forward) axes.
    """
    c, s = np.cos(roll_rad), np.sin(roll_rad)
    roll = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return roll @ look_rotation(heading_rad, pitch_rad)


def similarity_fit(src: np.ndarray, dst: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Similarity ``dst ~ s R src + t`` by least squares (Umeyama 1991).

    Args:
        src, dst: (N, 3) corresponding points, N >= 3.

    Returns:
        ``(s, R (3, 3), t (3,))``.
    """
    src, dst = np.asarray(src, np.float64), np.asarray(dst, np.float64)
    mu_s, mu_d = src.mean(0), dst.mean(0)
    a, b = src - mu_s, dst - mu_d
    U, S, Vt = np.linalg.svd(b.T @ a / len(src))
    D = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        D[2, 2] = -1
    R = U @ D @ Vt
    var = float((a**2).sum() / len(src))
    s = float(np.trace(np.diag(S) @ D) / var) if var > 0 else 1.0
    return s, R, mu_d - s * R @ mu_s


def view_direction(heading_rad: float, pitch_rad: float = 0.0) -> np.ndarray:
    """(3,) unit viewing direction of a camera with this heading and tilt (z up)."""
    cp = np.cos(pitch_rad)
    return np.array([cp * np.cos(heading_rad), cp * np.sin(heading_rad), np.sin(pitch_rad)])


def rotation_angle_deg(R: np.ndarray) -> float:
    """The angle (deg) of a rotation matrix ``R`` (3, 3)."""
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))))


def mount_pitch(R_cam_from_world: np.ndarray) -> float:
    """The tilt (rad, up positive) of a robot's camera on its mount, from a map: the median
    pitch of the photos' optical axes (``R_cam_from_world`` (N, 3, 3); the map frame's z is
    up). A robot's camera does not tilt as the robot drives, so every photo shows the mount;
    0 for no photo."""
    R = np.asarray(R_cam_from_world, np.float64).reshape(-1, 3, 3)
    if not len(R):
        return 0.0
    return float(np.median(np.arcsin(np.clip(R[:, 2, 2], -1.0, 1.0))))


def map_mount(rec) -> tuple[float, float]:
    """The camera plane's height and the mount's pitch (rad) of a robot's map (a
    ``pycolmap.Reconstruction``): the median height of its camera centres and
    :func:`mount_pitch` of its photos (0, 0 for no photo)."""
    ids = list(rec.reg_image_ids())
    if not ids:
        return 0.0, 0.0
    heights = [rec.image(i).projection_center()[2] for i in ids]
    rot = np.array([rec.image(i).cam_from_world().rotation.matrix() for i in ids])
    return float(np.median(heights)), mount_pitch(rot)


def planar_cam_from_world(x: np.ndarray, y: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Rotation and translation of horizontal cameras at height z = 0 (``look_rotation`` with
    no pitch, for many cameras at once).

    Args:
        x: (N,) camera centre x (m).
        y: (N,) camera centre y (m).
        theta: (N,) heading (rad).

    Returns:
        (N, 12) array: R row-major (9) then t (3), cam_from_world.
    """
    x, y, theta = (np.atleast_1d(np.asarray(a, dtype=np.float64)) for a in (x, y, theta))
    c, s = np.cos(theta), np.sin(theta)
    z0, one = np.zeros_like(c), np.ones_like(c)
    # rows: x_cam (right) = (s, -c, 0); y_cam (down) = (0, 0, -1); z_cam (forward) = (c, s, 0)
    R = np.stack([s, -c, z0, z0, z0, -one, c, s, z0], axis=1).reshape(-1, 3, 3)
    C = np.stack([x, y, z0], axis=1)
    t = -np.einsum("nij,nj->ni", R, C)
    return np.concatenate([R.reshape(-1, 9), t], axis=1)


def tilted_cam_from_world(xyz: np.ndarray, theta: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    """Rotation and translation of cameras anywhere, looking along ``theta`` tilted up by
    ``pitch``, with no roll (``look_rotation`` for many cameras at once; a person's camera).

    Args:
        xyz: (N, 3) camera centres (m).
        theta: (N,) heading (rad).
        pitch: (N,) tilt (rad, up positive).

    Returns:
        (N, 12) array: R row-major (9) then t (3), cam_from_world.
    """
    C = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    th, pi = (np.atleast_1d(np.asarray(a, dtype=np.float64)) for a in (theta, pitch))
    ch, sh, cp, sp = np.cos(th), np.sin(th), np.cos(pi), np.sin(pi)
    fwd = np.stack([cp * ch, cp * sh, sp], axis=1)
    right = np.stack([sh, -ch, np.zeros_like(ch)], axis=1)
    down = np.cross(fwd, right)
    R = np.stack([right, down, fwd], axis=1)  # rows: camera x, y, z axes
    t = -np.einsum("nij,nj->ni", R, C)
    return np.concatenate([R.reshape(-1, 9), t], axis=1)


def frustum_lines(poses: np.ndarray, intr: Intrinsics, depth: float) -> np.ndarray:
    """Edges of camera frusta: centre to the four far corners, and the far rectangle.

    Args:
        poses: (N, 5) x, y, z (m), theta, pitch (rad).
        intr: the camera.
        depth: distance of the far rectangle (m).

    Returns:
        (N, 8, 2, 3) line segments (m).
    """
    Rt = tilted_cam_from_world(poses[:, :3], poses[:, 3], poses[:, 4])
    R = Rt[:, :9].reshape(-1, 3, 3)
    u = np.array([0.0, intr.width, intr.width, 0.0])
    v = np.array([0.0, 0.0, intr.height, intr.height])
    cam = np.stack([(u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, np.ones(4)], 1) * depth
    corners = poses[:, None, :3] + np.einsum("nji,kj->nki", R, cam)  # (N, 4, 3)
    C = np.broadcast_to(poses[:, None, :3], corners.shape)
    rays = np.stack([C, corners], axis=2)
    rim = np.stack([corners, np.roll(corners, -1, axis=1)], axis=2)
    return np.concatenate([rays, rim], axis=1)


def robot_xy_for_camera(
    camera_xy: np.ndarray, heading: float, camera_offset_m: tuple[float, float]
) -> np.ndarray:
    """Where the robot's rotation axis is when its camera centre is at ``camera_xy``.

    Args:
        camera_xy: (2,) camera centre (m).
        heading: robot heading (rad).
        camera_offset_m: camera centre (forward, left) of the rotation axis (m).
    """
    fwd, left = camera_offset_m
    c, s = np.cos(heading), np.sin(heading)
    return np.asarray(camera_xy, float) - np.array([fwd * c - left * s, fwd * s + left * c])


def read_map_geometry(sfm_dir: Path, with_headings: bool = False):
    """3D points and camera centres of a COLMAP model.

    Args:
        sfm_dir: folder with cameras.bin, images.bin, points3D.bin.

    Returns:
        points (N, 3) m, camera centres (M, 3) m of the registered images and their names in
        image-name order; with ``with_headings`` also (M,) headings (rad) of the optical axes.

    Raises:
        FileNotFoundError: the folder does not hold a COLMAP model.
    """
    import pycolmap

    sfm_dir = Path(sfm_dir)
    if not (sfm_dir / "images.bin").exists() and not (sfm_dir / "images.txt").exists():
        raise FileNotFoundError(
            f"{sfm_dir}: no COLMAP model (images.bin); run the sfm stage for this round first"
        )
    rec = pycolmap.Reconstruction(str(sfm_dir))
    pts = np.array([p.xyz for p in rec.points3D.values()], float).reshape(-1, 3)
    imgs = sorted((im for im in rec.images.values() if im.has_pose), key=lambda im: im.name)
    centres = np.array([im.projection_center() for im in imgs], float).reshape(-1, 3)
    names = [im.name for im in imgs]
    if not with_headings:
        return pts, centres, names
    fwd = [np.asarray(im.cam_from_world().rotation.matrix())[2] for im in imgs]
    headings = np.array([np.arctan2(f[1], f[0]) for f in fwd], float)
    return pts, centres, names, headings


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
