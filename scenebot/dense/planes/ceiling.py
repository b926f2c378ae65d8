"""Step 1 of the plane fill, continued: the ceiling.

The ceiling, which a level camera sees only in its photos' top rows, at grazing angles, is
too small a share of the cloud for RANSAC: it is found as the highest dense height of the
points with vertical normals, above every camera, with nothing measured above it
(:func:`find_ceiling`).
"""

from __future__ import annotations

import numpy as np

from scenebot.dense.planes.detect import LEVEL_DEG
from scenebot.dense.planes.geometry import Plane, plane_extent


def find_ceiling(
    points: np.ndarray,
    normals: np.ndarray,
    planes: list[Plane],
    centres: np.ndarray,
    distance_m: float,
    normal_deg: float,
    min_points: int,
    cell_m: float,
    min_cell_points: int,
    close_cells: int,
    max_beyond: float = 0.25,
    above_m: float = 0.1,
    band_m: float = 0.15,
    peak_ratio: float = 3.0,
) -> Plane | None:
    """The room's ceiling, from the few points a level camera measures on it.

    A camera at robot height sees the ceiling only in the top rows of its photos, at
    grazing angles from metres away: a few thousand measured pixels over a whole campaign,
    too few for RANSAC's share of the cloud, though the ceiling is a sixth of the room's
    surface. Indoors it is the highest horizontal surface, and nothing lies above it: the
    ceiling is the highest height (along the floor's normal, above every camera) where at
    least ``min_points`` points whose normals are vertical within ``normal_deg`` lie within
    ``distance_m``, and ``peak_ratio`` times as many as the same width holds on average
    within ``band_m`` around it (a surface, not a smear of stray points), with fewer points
    measured more than ``above_m`` above it than ``max_beyond`` times those within
    ``above_m`` of it (grazing rays from metres away put its points a few cm off).

    Args:
        points, normals: (N, 3) the thinned cloud and its unit normals.
        planes: the planes found so far; the largest near-horizontal one is the floor.
        centres: (V, 3) camera centres.
        distance_m: inlier distance (m).
        normal_deg: largest angle between a point's normal and the vertical.
        min_points: fewest inliers of a ceiling.
        cell_m, min_cell_points, close_cells: its extent raster
            (:func:`~scenebot.dense.planes.geometry.plane_extent`).
        max_beyond: share of the points around it that may lie above it (outliers).
        above_m: how far above it a point counts as above.
        band_m, peak_ratio: the peak test.

    Returns:
        The ceiling plane (its normal the floor's), or None when there is no floor, no
        height holds enough points, depth was measured above it, or RANSAC found it.
    """
    floors = [p for p in planes if abs(p.normal[2]) > np.cos(np.radians(LEVEL_DEG))]
    if not floors or len(points) == 0 or len(centres) == 0:
        return None
    floor = max(floors, key=lambda p: p.inliers)
    n = floor.normal
    up = n if np.median(centres @ n + floor.offset) > 0 else -n
    top = float((centres @ up).max()) + distance_m
    cos_n = np.cos(np.radians(normal_deg))
    h = points @ up
    vertical = np.abs(normals @ up) > cos_n
    cand = vertical & (h > top)
    if cand.sum() < min_points:
        return None
    height = _peak_height(h[cand], distance_m, min_points, above_m, band_m, peak_ratio)
    if height is None:
        return None
    inl = cand & (np.abs(h - height) < distance_m)
    height = float(np.median(h[inl]))
    inl = cand & (np.abs(h - height) < distance_m)
    if int((h > height + above_m).sum()) > max_beyond * int((np.abs(h - height) <= above_m).sum()):
        return None  # measured depth above it: not the room's top
    for p in planes:  # RANSAC found it already
        if abs(p.normal @ up) > cos_n and float(p.origin @ up) > height - above_m:
            return None
    x = points[inl]
    origin = x.mean(0)
    origin = origin - (origin @ up - height) * up
    basis = floor.basis.copy()  # the floor's raster axes: span_floor maps cell to cell
    lo, occ = plane_extent((x - origin) @ basis.T, cell_m, min_cell_points, close_cells)
    return Plane(up.copy(), -height, basis, origin, cell_m, lo, occ, int(inl.sum()))


def _peak_height(
    heights: np.ndarray, distance_m: float, min_points: int, above_m: float, band_m: float,
    peak_ratio: float,
) -> float | None:  # fmt: skip
    """The highest height holding ``min_points`` of ``heights`` within ``distance_m``, a
    peak: ``peak_ratio`` times as many as the same width holds on average within
    ``band_m``; of the dense heights within ``above_m`` below it, the densest (the peak,
    not its edge). None when no height is dense."""
    hs = np.sort(heights)
    lo_i = np.searchsorted(hs, hs - distance_m, "left")
    hi_i = np.searchsorted(hs, hs + distance_m, "right")
    count = hi_i - lo_i
    around = np.searchsorted(hs, hs + band_m, "right") - np.searchsorted(hs, hs - band_m, "left")
    background = (around - count) * distance_m / max(band_m - distance_m, 1e-9)
    dense = np.flatnonzero((count >= min_points) & (count >= peak_ratio * background))
    if not len(dense):
        return None
    k = dense[-1]
    near = dense[hs[dense] > hs[k] - above_m]
    return float(hs[near[np.argmax(count[near])]])
