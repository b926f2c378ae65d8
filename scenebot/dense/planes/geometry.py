"""A plane with its extent, and the ray geometry every step of the plane fill shares:
back-projection of a depth map, a view's rays through its measured pixels, where a ray
meets a plane, and when measured depth lies behind a plane."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Plane:
    """``normal @ x + offset = 0`` (unit normal) and its extent: the cells of an in-plane
    raster that hold inliers (after a morphological closing that bridges small gaps).

    Attributes:
        normal: (3,) unit normal.
        offset: the plane's offset (m).
        basis: (2, 3) orthonormal in-plane axes.
        origin: (3,) a point of the plane (inlier centroid).
        cell_m: raster cell size (m).
        lo: (2,) plane coordinates of the raster's corner.
        occupied: (H, W) bool raster of the extent.
        inliers: number of voxel points on it.
        boundary: a boundary of the room (nothing measured past it): its extent is its carved
            hull (:func:`~scenebot.dense.planes.extents.carved_hulls`), and a fill may reach
            past its cells by the margin.
    """

    normal: np.ndarray
    offset: float
    basis: np.ndarray
    origin: np.ndarray
    cell_m: float
    lo: np.ndarray
    occupied: np.ndarray
    inliers: int
    boundary: bool = False

    def to_2d(self, x: np.ndarray) -> np.ndarray:
        """(N, 3) points -> (N, 2) plane coordinates."""
        # a contiguous (3, 2) matrix: numpy's product with the transposed view is 4x slower
        return (np.asarray(x) - self.origin) @ np.ascontiguousarray(self.basis.T)

    def cells(self, x: np.ndarray) -> np.ndarray:
        """(N, 2) int64 raster indices of the points' projections (may lie off the raster)."""
        return np.floor((self.to_2d(x) - self.lo) / self.cell_m).astype(np.int64)

    def grown(self, margin: float) -> np.ndarray:
        """The extent raster grown by ``margin`` m (itself for ``margin <= 0``)."""
        if margin <= 0:
            return self.occupied
        from scipy.ndimage import binary_dilation

        return binary_dilation(self.occupied, iterations=int(np.ceil(margin / self.cell_m)))

    def inside(self, x: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """(N,) bool: the points' projections fall in the extent (grown by ``margin`` m)."""
        return in_raster(self.grown(margin), self.cells(x))

    def cell_centres(self) -> tuple[np.ndarray, np.ndarray]:
        """The extent's cells: their (K, 2) raster indices and (K, 3) centres (m)."""
        ij = np.argwhere(self.occupied)
        return ij, self.origin + (self.lo + (ij + 0.5) * self.cell_m) @ self.basis

    @property
    def area_m2(self) -> float:
        return float(self.occupied.sum()) * self.cell_m**2


def in_raster(occ: np.ndarray, ij: np.ndarray) -> np.ndarray:
    """(N,) bool: the raster ``occ`` is set at the (N, 2) indices ``ij`` (False off it)."""
    ok = (ij[:, 0] >= 0) & (ij[:, 0] < occ.shape[0]) & (ij[:, 1] >= 0)
    ok &= ij[:, 1] < occ.shape[1]
    out = np.zeros(len(ij), bool)
    out[ok] = occ[ij[ok, 0], ij[ok, 1]]
    return out


def image_window(
    plane: Plane, K: np.ndarray, R: np.ndarray, t: np.ndarray, shape: tuple[int, int]
) -> tuple[slice, slice] | None:
    """The rows and columns (slices) of the pixels of a view (``shape``) whose rays may
    meet the plane's raster in front of the camera, a pixel of margin around them; None
    when no ray does. Every pixel when the plane passes within 1 cm of the camera.

    A ray through a pixel meets the raster's rectangle at a point that projects onto that
    pixel: the pixels lie in the bounding box of the rectangle's projection, clipped at 1 mm
    before the camera (a point nearer than that lies within 1 cm of the camera)."""
    h, w = shape
    if abs(-(R.T @ t) @ plane.normal + plane.offset) < 0.01:
        return slice(0, h), slice(0, w)
    hi = plane.lo + np.array(plane.occupied.shape) * plane.cell_m
    corners = np.array([plane.lo, [hi[0], plane.lo[1]], hi, [plane.lo[0], hi[1]]])
    cam = _clip_near((plane.origin + corners @ plane.basis) @ R.T + t, 1e-3)
    if len(cam) == 0:
        return None
    u = K[0, 0] * cam[:, 0] / cam[:, 2] + K[0, 2] - 0.5  # pixel j's ray passes u = j + 0.5
    v = K[1, 1] * cam[:, 1] / cam[:, 2] + K[1, 2] - 0.5
    c0, c1 = max(int(np.floor(u.min())) - 1, 0), min(int(np.ceil(u.max())) + 2, w)
    r0, r1 = max(int(np.floor(v.min())) - 1, 0), min(int(np.ceil(v.max())) + 2, h)
    if c0 >= c1 or r0 >= r1:
        return None
    return slice(r0, r1), slice(c0, c1)


def _clip_near(poly: np.ndarray, near: float) -> np.ndarray:
    """The part of a convex polygon ((N, 3) camera-frame vertices) with z >= ``near``."""
    out = []
    for k in range(len(poly)):
        a, b = poly[k], poly[(k + 1) % len(poly)]
        if a[2] >= near:
            out.append(a)
        if (a[2] >= near) != (b[2] >= near):
            out.append(a + (near - a[2]) / (b[2] - a[2]) * (b - a))
    return np.array(out).reshape(-1, 3)


def plane_extent(
    p2: np.ndarray, cell_m: float, min_points: int, close_cells: int
) -> tuple[np.ndarray, np.ndarray]:
    """Raster of the cells holding ``min_points`` in-plane points, closed over
    ``close_cells`` cells; returns its corner and the (H, W) bool raster."""
    from scipy.ndimage import binary_closing

    lo = p2.min(0) - (close_cells + 1) * cell_m
    ij = np.floor((p2 - lo) / cell_m).astype(np.int64)
    shape = ij.max(0) + close_cells + 2
    counts = np.zeros(shape, np.int32)
    np.add.at(counts, (ij[:, 0], ij[:, 1]), 1)
    occ = counts >= min_points
    if close_cells > 0:
        occ = binary_closing(occ, iterations=close_cells)
    return lo, occ


def backproject(depth: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(H, W) z-depth -> (H, W, 3) world points (COLMAP pixel centres at +0.5)."""
    h, w = depth.shape
    v, u = np.mgrid[0:h, 0:w].astype(np.float64) + 0.5
    x = (u - K[0, 2]) / K[0, 0] * depth
    y = (v - K[1, 2]) / K[1, 1] * depth
    cam = np.stack([x, y, depth.astype(np.float64)], -1)
    return (cam - t) @ R  # R^T (x - t)


def backproject_pixels(
    z: np.ndarray, v: np.ndarray, u: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray
) -> np.ndarray:
    """(N,) z-depths at pixels (row ``v``, column ``u``) -> (N, 3) world points, as
    :func:`backproject` computes them."""
    x = (u + 0.5 - K[0, 2]) / K[0, 0] * z
    y = (v + 0.5 - K[1, 2]) / K[1, 1] * z
    cam = np.stack([x, y, z.astype(np.float64)], -1)
    return (cam - t) @ R


def camera_rays(uu: np.ndarray, vv: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Camera-frame rays with unit z through the centres of pixels (column ``uu``, row
    ``vv``, integer arrays of any shape): shape ``uu.shape + (3,)``."""
    return np.stack(
        [(uu + 0.5 - K[0, 2]) / K[0, 0], (vv + 0.5 - K[1, 2]) / K[1, 1], np.ones(uu.shape)], -1
    )


@dataclass
class MeasuredRays:
    """Every ``stride``-th pixel with measured depth of one view, as rays.

    Attributes:
        z: (N,) measured z-depth (m).
        ray: (N, 3) world directions with unit camera z.
        centre: (3,) camera centre.
    """

    z: np.ndarray
    ray: np.ndarray
    centre: np.ndarray

    @classmethod
    def of_view(
        cls, depth: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray, stride: int
    ) -> MeasuredRays:
        d = depth[::stride, ::stride]
        vv, uu = np.mgrid[0 : depth.shape[0] : stride, 0 : depth.shape[1] : stride]
        m = d > 0
        z_meas = d[m].astype(np.float64)
        return cls(z_meas, camera_rays(uu[m], vv[m], K) @ R, -R.T @ t)

    @property
    def points(self) -> np.ndarray:
        """(N, 3) the measured points (world)."""
        return self.centre + self.z[:, None] * self.ray

    def on_plane_tolerance(self, distance_m: float, rel_distance: float) -> np.ndarray:
        """(N,) how far from a plane a point still lies on it: the larger of
        ``distance_m`` and ``rel_distance`` of its depth."""
        return np.maximum(distance_m, rel_distance * self.z)


def ray_plane_depth(plane: Plane, centre: np.ndarray, ray: np.ndarray) -> np.ndarray:
    """(N,) z-depth where rays (unit camera z) from ``centre`` meet the plane (inf or nan
    where they run parallel to it; negative behind the camera)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return -(centre @ plane.normal + plane.offset) / (ray @ plane.normal)


def behind_limit(z_meas: np.ndarray, distance_m: float, rel_distance: float) -> np.ndarray:
    """A plane met nearer than this along a ray lies before the ray's measured depth
    ``z_meas`` by more than ``rel_distance`` of it and ``2 * distance_m``: the measured
    point lies behind the plane."""
    return z_meas * (1 - rel_distance) - 2 * distance_m


def crossed_before(
    plane: Plane, rays: MeasuredRays, distance_m: float, rel_distance: float
) -> tuple[np.ndarray, np.ndarray]:
    """Where the rays meet the plane (z-depth, (N,)) and which meet it in front of the
    camera and before their measured depth (:func:`behind_limit`): (N,) bool."""
    z = ray_plane_depth(plane, rays.centre, rays.ray)
    return z, np.isfinite(z) & (z > 0) & (z < behind_limit(rays.z, distance_m, rel_distance))
