"""Cameras of the tour: COLMAP camera models reduced to one OpenCV-style parameter vector.

Pixel (i, j) has its centre at ``(j + 0.5, i + 0.5)`` like COLMAP. A pose is cam_from_world
``x_cam = R @ x_world + t`` (metres), camera axes x right, y down, z forward.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from scenebot.geometry import look_rotation as look_rotation  # re-exported (tests)

# COLMAP model name -> how its params map onto (fx, fy, cx, cy, k1, k2, p1, p2)
_MODELS = {
    "SIMPLE_PINHOLE": lambda p: (p[0], p[0], p[1], p[2], 0, 0, 0, 0),
    "PINHOLE": lambda p: (p[0], p[1], p[2], p[3], 0, 0, 0, 0),
    "SIMPLE_RADIAL": lambda p: (p[0], p[0], p[1], p[2], p[3], 0, 0, 0),
    "RADIAL": lambda p: (p[0], p[0], p[1], p[2], p[3], p[4], 0, 0),
    "OPENCV": lambda p: (p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7]),
}


class TourInputError(ValueError):
    """An input of the tour stage is unusable; the message names the file or setting."""


@dataclass(frozen=True)
class Camera:
    """Pinhole camera with OpenCV radial-tangential distortion (k1, k2, p1, p2).

    Attributes:
        width: image width, pixels.
        height: image height, pixels.
        params: (8,) float64 ``fx, fy, cx, cy, k1, k2, p1, p2`` (pixels; distortion unitless).
    """

    width: int
    height: int
    params: tuple[float, ...]

    @staticmethod
    def from_pycolmap(cam) -> Camera:
        """Convert a ``pycolmap.Camera`` (SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV).

        Raises:
            TourInputError: another camera model.
        """
        name = str(cam.model.name) if hasattr(cam.model, "name") else str(cam.model)
        name = name.split(".")[-1]
        if name not in _MODELS:
            raise TourInputError(
                f"camera {cam.camera_id} uses the COLMAP model {name}; the tour renderer supports "
                f"{', '.join(_MODELS)}: re-run SfM with one of them (sfm camera_model setting)"
            )
        p = np.asarray(cam.params, np.float64)
        return Camera(int(cam.width), int(cam.height), tuple(float(v) for v in _MODELS[name](p)))

    @staticmethod
    def pinhole(width: int, height: int, hfov_deg: float) -> Camera:
        """An undistorted camera with the given horizontal field of view (degrees)."""
        f = 0.5 * width / np.tan(np.radians(hfov_deg) / 2)
        return Camera(width, height, (f, f, width / 2, height / 2, 0.0, 0.0, 0.0, 0.0))

    @property
    def hfov_deg(self) -> float:
        """Horizontal field of view, degrees (ignoring distortion)."""
        return float(np.degrees(2 * np.arctan(0.5 * self.width / self.params[0])))

    def resized(self, width: int, height: int) -> Camera:
        """The same camera sampled at another image size (distortion unchanged)."""
        sx, sy = width / self.width, height / self.height
        fx, fy, cx, cy, *dist = self.params
        return Camera(width, height, (fx * sx, fy * sy, cx * sx, cy * sy, *dist))

    def as_array(self) -> np.ndarray:
        """(8,) float32 parameter vector for the taichi kernels."""
        return np.asarray(self.params, np.float32)

    def pixel_rays(self) -> np.ndarray:
        """Camera-frame rays through every pixel centre, scaled to z = 1.

        Returns:
            (H, W, 3) float32 rays ``(x, y, 1)``; a point at z-depth d is ``d * ray``.
        """
        fx, fy, cx, cy, k1, k2, p1, p2 = self.params
        u, v = np.meshgrid(np.arange(self.width) + 0.5, np.arange(self.height) + 0.5)
        pix = np.stack([u, v], -1).reshape(-1, 1, 2).astype(np.float64)
        if any(abs(d) > 0 for d in (k1, k2, p1, p2)):
            K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])
            xy = cv2.undistortPoints(
                pix, K, np.array([k1, k2, p1, p2]), criteria=(3, 20, 1e-9)
            ).reshape(-1, 2)
        else:
            xy = np.stack([(pix[:, 0, 0] - cx) / fx, (pix[:, 0, 1] - cy) / fy], -1)
        rays = np.concatenate([xy, np.ones((len(xy), 1))], 1)
        return rays.reshape(self.height, self.width, 3).astype(np.float32)

    def project(self, x_cam: np.ndarray) -> np.ndarray:
        """Project camera-frame points (N, 3) (z > 0) to pixel coordinates (N, 2)."""
        fx, fy, cx, cy, k1, k2, p1, p2 = self.params
        x = x_cam[:, 0] / x_cam[:, 2]
        y = x_cam[:, 1] / x_cam[:, 2]
        r2 = x * x + y * y
        rad = 1 + k1 * r2 + k2 * r2 * r2
        xd = x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        return np.stack([fx * xd + cx, fy * yd + cy], -1)
