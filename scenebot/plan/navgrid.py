"""The navigation grid: obstacle-point counts s(c) and KDE costs K(c) (paper section IV.B, eq. 1).

The grid covers the bounding box of the explored area (the camera centres) plus a margin, with
about ``n_cells`` cells along its larger dimension. Cell ``(iy, ix)`` covers
``origin + [ix, ix + 1) * cell_m`` in x and ``origin + [iy, iy + 1) * cell_m`` in y; arrays
are indexed ``[iy, ix]`` (row = y).

Each cell's score s(c) is the number of 3D points above the obstacle threshold z in it. The
cost is the kernel density estimate of eq. 1,

    K(c) = 1/|N| * sum_{c_i in N} w(c, c_i) s(c_i),    w = exp(-d^2 / (2 sigma^2)),

computed as a separable convolution (a 1D Gaussian along x, then along y). The planner uses
the Gaussian-weighted point count ``|N| * K(c)`` ("obstacle score", in points) so that the
settings do not depend on the size of N: a cell is *lethal* when its score reaches
``lethal_points`` (grown by ``inflate_m``), and otherwise costs ``1 + cost_weight * score`` per
metre travelled in it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from scenebot.plan.config import PlanConfig


@dataclass(frozen=True)
class GridGeometry:
    """Where the grid lies in the map frame.

    Attributes:
        origin_xy: map-frame (x, y) in metres of the outer corner of cell (0, 0).
        cell_m: cell edge length (m).
        shape: ``(ny, nx)`` number of cells along y and x.
    """

    origin_xy: tuple[float, float]
    cell_m: float
    shape: tuple[int, int]

    @staticmethod
    def around(lo_xy: np.ndarray, hi_xy: np.ndarray, n_cells: int) -> GridGeometry:
        """A grid centred on the box ``[lo_xy, hi_xy]`` with ``n_cells`` along its larger side.

        Args:
            lo_xy: (2,) lower corner of the box (m).
            hi_xy: (2,) upper corner of the box (m).
            n_cells: cells along the larger dimension.
        """
        lo = np.asarray(lo_xy, float)
        hi = np.asarray(hi_xy, float)
        size = np.maximum(hi - lo, 1e-6)
        cell = float(size.max()) / n_cells
        nx = max(1, math.ceil(size[0] / cell - 1e-9))
        ny = max(1, math.ceil(size[1] / cell - 1e-9))
        centre = (lo + hi) / 2.0
        origin = centre - 0.5 * cell * np.array([nx, ny])
        return GridGeometry((float(origin[0]), float(origin[1])), cell, (ny, nx))

    def cell_of(self, xy: np.ndarray) -> np.ndarray:
        """Cell indices ``(iy, ix)`` of map points; may lie outside the grid.

        Args:
            xy: (..., 2) map-frame positions (m).

        Returns:
            (..., 2) int64 ``[iy, ix]``.
        """
        xy = np.asarray(xy, float)
        ix = np.floor((xy[..., 0] - self.origin_xy[0]) / self.cell_m).astype(np.int64)
        iy = np.floor((xy[..., 1] - self.origin_xy[1]) / self.cell_m).astype(np.int64)
        return np.stack([iy, ix], axis=-1)

    def centre_of(self, cells: np.ndarray) -> np.ndarray:
        """Map-frame (x, y) of cell centres.

        Args:
            cells: (..., 2) ``[iy, ix]`` indices.

        Returns:
            (..., 2) positions (m).
        """
        c = np.asarray(cells, float)
        x = self.origin_xy[0] + (c[..., 1] + 0.5) * self.cell_m
        y = self.origin_xy[1] + (c[..., 0] + 0.5) * self.cell_m
        return np.stack([x, y], axis=-1)

    def contains_cell(self, cell: np.ndarray) -> bool:
        """Whether the ``[iy, ix]`` cell index lies inside the grid."""
        iy, ix = int(cell[0]), int(cell[1])
        return 0 <= iy < self.shape[0] and 0 <= ix < self.shape[1]


def gaussian_kernel_1d(sigma_cells: float, truncate: float) -> np.ndarray:
    """Unnormalised Gaussian weights ``exp(-d^2 / (2 sigma^2))`` for ``d = -r..r`` cells.

    Returns:
        (2r + 1,) weights with peak 1, ``r = ceil(truncate * sigma_cells)``.
    """
    r = max(1, math.ceil(truncate * sigma_cells))
    d = np.arange(-r, r + 1, dtype=float)
    return np.exp(-(d**2) / (2.0 * sigma_cells**2))


def kde_cost(counts: np.ndarray, sigma_cells: float, truncate: float = 3.0) -> np.ndarray:
    """Eq. 1: ``K(c) = 1/|N| sum w(c, c_i) s(c_i)`` as a separable Gaussian convolution.

    Args:
        counts: (ny, nx) obstacle point counts s(c).
        sigma_cells: Gaussian standard deviation in cells.
        truncate: N spans ``ceil(truncate * sigma)`` cells each way.

    Returns:
        (ny, nx) float64 K(c); cells outside the grid count as empty.
    """
    w = gaussian_kernel_1d(sigma_cells, truncate).astype(np.float32)
    s = np.ascontiguousarray(counts, dtype=np.float32)
    # Separable: one 1D pass along x, one along y (OpenCV, float32: relative error ~1e-6).
    k = cv2.sepFilter2D(s, cv2.CV_32F, w, w, borderType=cv2.BORDER_CONSTANT)
    return np.maximum(k.astype(np.float64), 0.0) / float(w.size * w.size)


@dataclass
class NavGrid:
    """A navigation grid with its geometry, counts, costs and lethal mask.

    Attributes:
        geometry: where the grid lies.
        counts: (ny, nx) int32 number of obstacle points per cell, s(c).
        kde: (ny, nx) float64 K(c) of eq. 1.
        score: (ny, nx) float64 Gaussian-weighted obstacle point count ``|N| * K(c)``.
        lethal: (ny, nx) bool cells treated as obstacles (score >= lethal_points, inflated).
        cost_per_m: (ny, nx) float64 travel cost per metre inside a cell
            (``1 + cost_weight * score``; lethal cells keep this value, the planner adds
            its own penalty).
    """

    geometry: GridGeometry
    counts: np.ndarray
    kde: np.ndarray
    score: np.ndarray
    lethal: np.ndarray
    cost_per_m: np.ndarray

    def save(self, path: Path) -> None:
        """Write the grid and its geometry to ``path`` (``.npz``)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        g = self.geometry
        np.savez_compressed(
            path,
            origin_xy=np.array(g.origin_xy, float),
            cell_m=np.array(g.cell_m, float),
            shape=np.array(g.shape, np.int64),
            counts=self.counts,
            kde=self.kde,
            score=self.score,
            lethal=self.lethal,
            cost_per_m=self.cost_per_m,
        )

    @staticmethod
    def load(path: Path) -> NavGrid:
        """Read a grid written by :meth:`save`."""
        with np.load(Path(path)) as z:
            g = GridGeometry(
                (float(z["origin_xy"][0]), float(z["origin_xy"][1])),
                float(z["cell_m"]),
                (int(z["shape"][0]), int(z["shape"][1])),
            )
            return NavGrid(
                g, z["counts"], z["kde"], z["score"], z["lethal"].astype(bool), z["cost_per_m"]
            )


def obstacle_counts(points_xyz: np.ndarray, geometry: GridGeometry, cfg: PlanConfig) -> np.ndarray:
    """s(c): the number of obstacle points (z above the threshold) in each cell.

    Args:
        points_xyz: (N, 3) map points (m).
        geometry: the grid.
        cfg: plan settings (``obstacle_z_min_m``, ``obstacle_z_max_m``).

    Returns:
        (ny, nx) int32 counts; points outside the grid are ignored.
    """
    p = np.asarray(points_xyz, float).reshape(-1, 3)
    keep = p[:, 2] > cfg.obstacle_z_min_m
    if cfg.obstacle_z_max_m is not None:
        keep &= p[:, 2] < cfg.obstacle_z_max_m
    ny, nx = geometry.shape
    fx = (p[keep, 0] - geometry.origin_xy[0]) / geometry.cell_m
    fy = (p[keep, 1] - geometry.origin_xy[1]) / geometry.cell_m
    inside = (fx >= 0) & (fx < nx) & (fy >= 0) & (fy < ny)
    flat = fy[inside].astype(np.int64) * nx + fx[inside].astype(np.int64)
    return np.bincount(flat, minlength=ny * nx).reshape(ny, nx).astype(np.int32)


def grid_from_counts(counts: np.ndarray, geometry: GridGeometry, cfg: PlanConfig) -> NavGrid:
    """Costs and lethal mask from the counts s(c) (eq. 1 plus inflation).

    Args:
        counts: (ny, nx) obstacle point counts.
        geometry: the grid.
        cfg: plan settings.
    """
    sigma_cells = cfg.kde_sigma_m / geometry.cell_m
    kde = kde_cost(counts, sigma_cells, cfg.kde_truncate)
    n_size = (2 * max(1, math.ceil(cfg.kde_truncate * sigma_cells)) + 1) ** 2
    score = kde * n_size
    lethal = score >= cfg.lethal_points
    r_cells = cfg.inflate_m / geometry.cell_m
    if r_cells >= 0.5 and lethal.any():
        # Distance (in cells) from each cell centre to the nearest lethal cell centre.
        free = (~lethal).astype(np.uint8)
        dist = cv2.distanceTransform(free, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        lethal = dist <= r_cells
    cost = 1.0 + cfg.cost_weight * score
    return NavGrid(geometry, np.asarray(counts, np.int32), kde, score, lethal, cost)


def build_navgrid(
    points_xyz: np.ndarray, camera_xy: np.ndarray, cfg: PlanConfig | None = None
) -> NavGrid:
    """The navigation grid of a map: centred on the explored area, costs from eq. 1.

    Args:
        points_xyz: (N, 3) sparse map points (m, map frame, camera plane z = 0).
        camera_xy: (M, 2) camera centres (m); their bounding box plus ``margin_m`` is the
            area covered by the grid.
        cfg: plan settings (defaults if None).

    Raises:
        ValueError: no camera centres were given.
    """
    cfg = cfg or PlanConfig()
    cams = np.asarray(camera_xy, float).reshape(-1, 2)
    if len(cams) == 0:
        raise ValueError("build_navgrid: no camera centres; the map has no registered images")
    lo = cams.min(axis=0) - cfg.margin_m
    hi = cams.max(axis=0) + cfg.margin_m
    geometry = GridGeometry.around(lo, hi, cfg.n_cells)
    return grid_from_counts(obstacle_counts(points_xyz, geometry, cfg), geometry, cfg)


def snap_to_free(grid: NavGrid, xy: np.ndarray, radius_m: float) -> np.ndarray | None:
    """``xy`` if its cell is free, else the centre of the nearest free cell within
    ``radius_m`` (m), else ``None`` (also when ``xy`` lies outside the grid).

    Args:
        grid: the navigation grid.
        xy: (2,) position (m, map frame).
        radius_m: how far the position may move.
    """
    geo = grid.geometry
    cell = geo.cell_of(xy)
    if not geo.contains_cell(cell):
        return None
    if not grid.lethal[cell[0], cell[1]]:
        return np.asarray(xy, float)
    k = int(np.ceil(radius_m / geo.cell_m))
    ny, nx = geo.shape
    r0, r1 = max(cell[0] - k, 0), min(cell[0] + k + 1, ny)
    c0, c1 = max(cell[1] - k, 0), min(cell[1] + k + 1, nx)
    rr, cc = np.mgrid[r0:r1, c0:c1]
    free = ~grid.lethal[r0:r1, c0:c1]
    if not free.any():
        return None
    centres = geo.centre_of(np.stack([rr[free], cc[free]], axis=-1))
    d = np.hypot(centres[:, 0] - xy[0], centres[:, 1] - xy[1])
    j = int(np.argmin(d))
    return centres[j] if d[j] <= radius_m else None
