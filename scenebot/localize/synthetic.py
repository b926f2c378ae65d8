"""Synthetic ground truth for localization tests and benchmarks (no SfM or simulator needed).

A box room with distinct textures on its six faces is ray-cast exactly (numpy). A map is made
from reference photos: every SIFT keypoint of a reference photo is back-projected onto the
known geometry; keypoints of different photos that land within ``merge_m`` of each other share
one 3D point id, so the map has several descriptors per point like the sfm stage's
``point_descriptors.npz``. Query photos at other poses then have exact true poses.

Frame: map frame with the camera plane at z = 0 (z up, metres); the floor is at
``-camera_height_m``. Camera axes as in OpenCV/COLMAP.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from scenebot.localize.features import extract_sift
from scenebot.localize.index import MapDescriptors


def camera_rotation(heading: float) -> np.ndarray:
    """cam_from_world rotation of a level camera looking along ``heading`` (rad, ccw from +x).

    Returns:
        (3, 3) rows: camera x (right), y (down), z (forward) in world coordinates.
    """
    fwd = np.array([math.cos(heading), math.sin(heading), 0.0])
    right = np.array([math.sin(heading), -math.cos(heading), 0.0])
    down = np.array([0.0, 0.0, -1.0])
    return np.stack([right, down, fwd])


def _texture(rng: np.random.Generator, n: int) -> np.ndarray:
    """A non-repeating multi-scale texture: smooth noise plus random shapes (uint8, n x n)."""
    img = np.zeros((n, n), np.float32)
    for s in (64, 16, 4):
        small = rng.random((n // s + 2, n // s + 2)).astype(np.float32)
        img += cv2.resize(small, (n, n), interpolation=cv2.INTER_CUBIC)[:n, :n] / 3.0
    img = (img - img.min()) / (np.ptp(img) + 1e-6) * 120 + 60
    img = img.astype(np.uint8)
    for _ in range(260):
        c = (int(rng.integers(0, n)), int(rng.integers(0, n)))
        col = int(rng.integers(0, 256))
        if rng.random() < 0.5:
            cv2.circle(img, c, int(rng.integers(4, 40)), col, -1)
        else:
            d = rng.integers(6, 60, 2)
            cv2.rectangle(img, c, (c[0] + int(d[0]), c[1] + int(d[1])), col, -1)
    return img


def _bilinear_wrap(tex: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear texture lookup with wrap-around; ``uv`` (n, 2) in texels, returns (n,)."""
    n = tex.shape[0]
    t = tex.astype(np.float32)
    u = uv[:, 0] - 0.5
    v = uv[:, 1] - 0.5
    u0 = np.floor(u).astype(np.int64)
    v0 = np.floor(v).astype(np.int64)
    fu = (u - u0).astype(np.float32)
    fv = (v - v0).astype(np.float32)
    u0 %= n
    v0 %= n
    u1 = (u0 + 1) % n
    v1 = (v0 + 1) % n
    top = t[v0, u0] * (1 - fu) + t[v0, u1] * fu
    bot = t[v1, u0] * (1 - fu) + t[v1, u1] * fu
    return top * (1 - fv) + bot * fv


@dataclass
class BoxRoom:
    """A textured box ``[0, sx] x [0, sy] x [-camera_height_m, sz - camera_height_m]``.

    Attributes:
        size_m: room size (x, y, z) in metres.
        camera_height_m: camera height above the floor (m).
        width, height: image size (px).
        focal_px: focal length (px); principal point at the image centre.
        texture_m: metres covered by one texture image side (textures repeat beyond it).
        seed: texture seed.
    """

    size_m: tuple[float, float, float] = (6.0, 5.0, 2.5)
    camera_height_m: float = 0.3
    width: int = 640
    height: int = 480
    focal_px: float = 520.0
    texture_m: float = 6.0
    seed: int = 0
    textures: list = field(init=False, repr=False)

    def __post_init__(self) -> None:
        rng = np.random.default_rng(self.seed)
        self.textures = [_texture(rng, 1024) for _ in range(6)]

    @property
    def K(self) -> np.ndarray:
        return np.array(
            [
                [self.focal_px, 0.0, self.width / 2.0],
                [0.0, self.focal_px, self.height / 2.0],
                [0.0, 0.0, 1.0],
            ]
        )

    def cast(self, origin: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Hit points and face ids of rays from inside the room.

        Args:
            origin: (3,) ray origin (m), inside the room.
            dirs: (n, 3) ray directions.

        Returns:
            points (n, 3) m and face ids (n,) int (0..5: x=0, x=sx, y=0, y=sy, floor, ceiling).
        """
        lo = np.array([0.0, 0.0, -self.camera_height_m])
        hi = lo + np.array(self.size_m)
        with np.errstate(divide="ignore", invalid="ignore"):
            t_lo = (lo - origin) / dirs
            t_hi = (hi - origin) / dirs
        cand = np.concatenate([t_lo, t_hi], axis=1)  # faces: x0 y0 z0 x1 y1 z1
        cand = np.where(cand > 1e-9, cand, np.inf)
        k = np.argmin(cand, axis=1)
        t = cand[np.arange(len(dirs)), k]
        face = np.array([0, 2, 4, 1, 3, 5])[k]
        return origin + dirs * t[:, None], face

    def _uv(self, p: np.ndarray, face: np.ndarray) -> np.ndarray:
        axes = {0: (1, 2), 1: (1, 2), 2: (0, 2), 3: (0, 2), 4: (0, 1), 5: (0, 1)}
        uv = np.zeros((len(p), 2))
        for f, (a, b) in axes.items():
            m = face == f
            uv[m, 0] = p[m, a]
            uv[m, 1] = p[m, b]
        return uv / self.texture_m * 1024.0

    def render(self, R: np.ndarray, center: np.ndarray) -> np.ndarray:
        """Grey photo (H, W) uint8 of the camera ``R`` (cam_from_world) at ``center`` (m).

        Supersampled 2x2 so that edges are antialiased like a real photo.
        """
        ss = 2
        h, w = self.height * ss, self.width * ss
        ys, xs = np.mgrid[0:h, 0:w]
        pix = np.stack([(xs + 0.5) / ss, (ys + 0.5) / ss], axis=-1).reshape(-1, 2)
        rays = np.c_[(pix - self.K[:2, 2]) / self.focal_px, np.ones(len(pix))] @ R
        p, face = self.cast(np.asarray(center, float), rays)
        uv = self._uv(p, face).astype(np.float32)
        out = np.zeros(len(p), np.float32)
        for f in range(6):
            m = face == f
            if m.any():
                out[m] = _bilinear_wrap(self.textures[f], uv[m])
        img = out.reshape(h, w)
        return cv2.resize(img, (self.width, self.height), interpolation=cv2.INTER_AREA).astype(
            np.uint8
        )

    def backproject(self, R: np.ndarray, center: np.ndarray, xy: np.ndarray) -> np.ndarray:
        """3D points (n, 3) seen at pixels ``xy`` (n, 2) (COLMAP convention)."""
        rays = np.c_[(np.asarray(xy) - self.K[:2, 2]) / self.focal_px, np.ones(len(xy))] @ R
        return self.cast(np.asarray(center, float), rays)[0]


def build_map(
    room: BoxRoom,
    poses: list[tuple[float, float, float]],
    merge_m: float = 0.01,
    first_octave: int = -1,
) -> MapDescriptors:
    """Map descriptors from reference photos at ``poses`` [(x, y, heading)] (m, rad).

    Keypoints whose back-projections fall in the same ``merge_m`` voxel share a point id.
    """
    xyz, desc = [], []
    for x, y, th in poses:
        R = camera_rotation(th)
        c = np.array([x, y, 0.0])
        kps, d = extract_sift(room.render(R, c), first_octave=first_octave)
        xyz.append(room.backproject(R, c, kps))
        desc.append(d)
    P = np.concatenate(xyz)
    D = np.concatenate(desc)
    _, inv = np.unique(np.floor(P / merge_m).astype(np.int64), axis=0, return_inverse=True)
    inv = inv.ravel().astype(np.int64)
    # A point's position: the mean of its observations.
    n = inv.max() + 1
    mean = np.zeros((n, 3))
    np.add.at(mean, inv, P)
    mean /= np.bincount(inv, minlength=n)[:, None]
    return MapDescriptors(inv, mean[inv], D)
