"""Step 2 of the plane fill: the extents of the room's boundary planes (``extent:
carved_hull``).

The room's boundary planes (walls, floor, ceiling: almost nothing measured past them) span
the convex hull of their cells, less the cells that measured depth is seen through (a
doorway). A plain wall then reaches between its posters and corners; a box face keeps its
own cells (:func:`carved_hulls`). With a ceiling, the walls rise to it
(``walls_to_ceiling_m``, :func:`span_to_ceiling`: a level camera measures the top of a wall
only from across the room), and the ceiling reaches their top edges (:func:`span_walls`:
the floor along a wall is often under furniture); the ceiling spans the floor's extent
(:func:`span_floor`).
"""

from __future__ import annotations

import logging
from collections.abc import Iterable

import numpy as np

from scenebot.dense.planes.geometry import MeasuredRays, Plane, crossed_before

LOG = logging.getLogger(__name__)

#: a plane within this angle (degrees) of the ceiling's or floor's normal is no wall
WALL_TILT_DEG = 10.0


def carved_hulls(
    planes: list[Plane],
    samples: Iterable[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]],
    *,
    distance_m: float,
    rel_distance: float,
    min_rays: int,
    stride: int = 4,
    max_beyond: float = 0.1,
    known: Iterable[int] = (),
) -> list[np.ndarray]:
    """The extents of the room's boundary planes widened to the convex hull of their cells,
    less what is seen through.

    A plain wall holds measured points only on its posters, edges and corners; the hull of
    those spans the wall between them. Only boundary planes are widened: those beyond
    which almost nothing was measured (fewer points than ``max_beyond`` times those on the
    plane), as the walls, floor and ceiling of a room. The face of a box or a cabinet has
    the room behind it, and its hull could reach where a plain wall behind it was never
    measured. Where measured depth lies beyond a plane along a ray that crosses its hull (a
    doorway, the far side of an opening), the crossing's cell is free space: a cell crossed
    by at least ``min_rays`` such rays, and by more of them than it holds measured points
    of the plane, is carved out, with its 8 neighbours.

    Args:
        planes: the planes (their ``occupied`` rasters: cells holding inliers).
        samples: ``(depth, K, R, t)`` of the views whose measured depth votes.
        distance_m, rel_distance: a point lies on a plane within the larger of these.
        min_rays: rays a cell needs to be carved.
        stride: every ``stride``-th pixel of a depth map votes.
        max_beyond: a plane is a boundary when the points measured beyond its extension
            outside the hull are fewer than this share of those on it.
        known: the indices of planes that are boundaries whatever that count says: the
            ceiling, which :func:`~scenebot.dense.planes.ceiling.find_ceiling` found as the
            room's top with nothing measured above it (its own test allows for the few
            centimetres grazing rays put its points off; here its few hundred points made
            101 beyond against 907 on, 11%, of an office campaign's ceiling too many: not
            widened, 4.8% of it within 2 cm instead of 59%).

    Returns:
        One (H, W) bool raster per plane, on the plane's own raster grid; the boundary
        planes are marked (``Plane.boundary``).
    """
    from scipy.ndimage import binary_dilation

    hulls = [_hull(pl.occupied) for pl in planes]
    through = [np.zeros(pl.occupied.shape, np.int64) for pl in planes]
    on = [np.zeros(pl.occupied.shape, np.int64) for pl in planes]
    beyond = np.zeros(len(planes), np.int64)
    for depth, K, R, t in samples:
        rays = MeasuredRays.of_view(depth, K, R, t, stride)
        if not len(rays.z):
            continue
        X = rays.points
        tol = rays.on_plane_tolerance(distance_m, rel_distance)
        for j, pl in enumerate(planes):
            _count_on(on[j], pl, X, tol)
            beyond[j] += _count_through(through[j], hulls[j], pl, rays, distance_m, rel_distance)
    out = []
    known = set(known)
    for j, (pl, hull, thr, onj) in enumerate(zip(planes, hulls, through, on, strict=True)):
        if j not in known and beyond[j] > max_beyond * onj.sum():
            LOG.info("dense: plane %d (normal %s, offset %.3f) is no boundary of the room: %d "
                     "measured points beyond it, %d on it", j, np.round(pl.normal, 2).tolist(),
                     pl.offset, beyond[j], onj.sum())  # fmt: skip
            out.append(pl.occupied)
            continue
        pl.boundary = True
        carved = binary_dilation((thr >= min_rays) & (thr > onj), np.ones((3, 3), bool))
        out.append(pl.occupied | (hull & ~carved))
    return out


def _hull(occupied: np.ndarray) -> np.ndarray:
    """The convex hull of a raster's cells, the cells included."""
    import cv2

    ij = np.argwhere(occupied)[:, ::-1].astype(np.int32)  # (x = column, y = row)
    hull = np.zeros(occupied.shape, np.uint8)
    cv2.fillConvexPoly(hull, cv2.convexHull(ij), 1)
    return hull.astype(bool) | occupied


def _count_on(on: np.ndarray, pl: Plane, X: np.ndarray, tol: np.ndarray) -> None:
    """Add to each raster cell of the plane (in place) the measured points ``X`` that lie
    on it (within ``tol``)."""
    shape = np.array(pl.occupied.shape)
    cell = np.floor((pl.to_2d(X) - pl.lo) / pl.cell_m).astype(np.int64)
    sel = (np.abs(X @ pl.normal + pl.offset) < tol) & np.all((cell >= 0) & (cell < shape), 1)
    np.add.at(on, (cell[sel, 0], cell[sel, 1]), 1)


def _count_through(
    through: np.ndarray, hull: np.ndarray, pl: Plane, rays: MeasuredRays, distance_m: float,
    rel_distance: float,
) -> int:  # fmt: skip
    """Add to each raster cell of the plane's hull (in place) the rays that cross it before
    their measured depth; returns how many cross the plane outside the hull (seen past the
    plane where it is not)."""
    z, cand = crossed_before(pl, rays, distance_m, rel_distance)
    if not cand.any():
        return 0
    shape = np.array(pl.occupied.shape)
    cell = np.floor((pl.to_2d(rays.centre + z[cand, None] * rays.ray[cand]) - pl.lo) / pl.cell_m)
    cell = cell.astype(np.int64)
    sel = np.all((cell >= 0) & (cell < shape), 1)
    in_hull = np.zeros(len(cell), bool)
    in_hull[sel] = hull[cell[sel, 0], cell[sel, 1]]
    np.add.at(through, (cell[in_hull, 0], cell[in_hull, 1]), 1)
    return int((~in_hull).sum())


def span_floor(ceiling: Plane, floor: Plane) -> None:
    """Widen a ceiling's extent (in place) by its floor's, projected up: the ceiling of a
    room spans its floor, though the camera saw only patches of it."""
    from scipy.ndimage import binary_closing

    _, X = floor.cell_centres()
    if not len(X):
        return
    X = X - np.outer(X @ ceiling.normal + ceiling.offset, ceiling.normal)  # onto the ceiling
    _, Y = ceiling.cell_centres()
    p2 = ceiling.to_2d(np.concatenate([X, Y]))
    lo = np.minimum(p2.min(0) - ceiling.cell_m, ceiling.lo)
    ij = np.floor((p2 - lo) / ceiling.cell_m).astype(np.int64)
    occ = np.zeros(ij.max(0) + 2, bool)
    occ[ij[:, 0], ij[:, 1]] = True
    ceiling.lo, ceiling.occupied = lo, binary_closing(occ, iterations=1) | occ


def span_to_ceiling(wall: Plane, ceiling: Plane, *, max_rise_m: float) -> int:
    """Raise a boundary wall's extent (in place) to the ceiling: every column of its raster
    rises from its highest cell up to the ceiling's height when that is less than
    ``max_rise_m`` above it.

    A level camera measures the top of a wall only from across the room, at grazing angles:
    its extent ends a few decimetres below the ceiling, though a room's walls meet it. Only
    upwards: a doorway between the floor and a lintel stays open, and a column with no cell
    (an opening to the ceiling) does not rise.

    Returns:
        The number of cells added.
    """
    up = ceiling.normal / np.linalg.norm(ceiling.normal)
    if abs(float(wall.normal @ up)) > np.sin(np.radians(WALL_TILT_DEG)):
        return 0  # not a wall
    new = _rising_points(wall, up, -ceiling.offset, max_rise_m)
    if not new:
        return 0
    return _add_cells(wall, np.concatenate(new))


def _rising_points(wall: Plane, up: np.ndarray, h_ceiling: float, max_rise_m: float) -> list:
    """Per column of the wall's raster whose highest cell lies less than ``max_rise_m``
    below ``h_ceiling`` (along ``up``), the points (one per cell) from it up to just below
    the ceiling."""
    cells, X = wall.cell_centres()
    if not len(cells):
        return []
    h = X @ up
    rise = up - (up @ wall.normal) * wall.normal
    rise /= np.linalg.norm(rise)
    new = []
    for i in np.unique(cells[:, 0]):
        col = cells[:, 0] == i
        k = int(np.argmax(np.where(col, h, -np.inf)))
        gap = h_ceiling - h[k]
        if 0 < gap < max_rise_m:
            steps = np.arange(1, int(np.ceil(gap / wall.cell_m)) + 1) * wall.cell_m
            top = X[k] + np.outer(np.minimum(steps, gap - 0.25 * wall.cell_m), rise)
            new.append(top)
    return new


def _add_cells(plane: Plane, points: np.ndarray) -> int:
    """Add the cells of in-plane ``points`` to the plane's extent (in place), the raster
    grown by whole cells where they fall outside it; returns the number of cells added."""
    p2 = plane.to_2d(points)
    ij = np.floor((p2 - plane.lo) / plane.cell_m).astype(np.int64)
    shift = np.maximum(-ij.min(0), 0)  # grow the raster by whole cells, grid kept
    ij = ij + shift
    shape = np.maximum(np.array(plane.occupied.shape) + shift, ij.max(0) + 1)
    occ = np.zeros(shape, bool)
    occ[
        shift[0] : shift[0] + plane.occupied.shape[0],
        shift[1] : shift[1] + plane.occupied.shape[1],
    ] = plane.occupied
    before = int(occ.sum())
    occ[ij[:, 0], ij[:, 1]] = True
    plane.lo = plane.lo - shift * plane.cell_m
    plane.occupied = occ
    return int(occ.sum()) - before


def span_walls(
    ceiling: Plane, walls: list[Plane], bridge_m: float = 0.6, centres: np.ndarray | None = None
) -> int:
    """Widen a ceiling's or a floor's extent (in place) to the edges of the room's walls
    where they meet it: the walls' cells within two cells of it (or past it) projected onto
    it, and the gaps between them and its own cells up to ``bridge_m`` closed. The floor
    along a wall is often under furniture, so the ceiling spanned from the floor
    (:func:`span_floor`) stops short of the wall it meets; the floor in a corner is seen only
    at grazing angles from across the room, so its carved hull cuts the corner off.

    Args:
        ceiling: the ceiling or the floor (its extent widened).
        walls: the room's walls (planes within 10 degrees of vertical to it are used).
        bridge_m: largest gap closed (m).
        centres: (C, 3) camera centres: "past it" is away from them; None: along the
            plane's normal (the ceiling's, which points up, away from the cameras).

    Returns:
        The number of cells added.
    """
    tops = _wall_edges(ceiling, walls, centres)
    if not tops or not sum(len(t) for t in tops):
        return 0
    return _bridge_cells(ceiling, ceiling.to_2d(np.concatenate(tops)), bridge_m)


def _wall_edges(plane: Plane, walls: list[Plane], centres: np.ndarray | None) -> list:
    """Per wall (within ``WALL_TILT_DEG`` of vertical to ``plane``), its cell centres
    within two cells of the plane or past it (see :func:`span_walls` for ``centres``)."""
    normal = plane.normal / np.linalg.norm(plane.normal)
    side = 1.0  # +1: "past it" is along the normal
    if centres is not None and len(centres):
        side = float(-np.sign(np.median(centres @ plane.normal + plane.offset))) or 1.0
    tops = []
    for w in walls:
        if abs(float(w.normal @ normal)) > np.sin(np.radians(WALL_TILT_DEG)):
            continue
        _, X = w.cell_centres()
        near = side * (X @ plane.normal + plane.offset) > -2 * w.cell_m  # cells at it
        tops.append(X[near])
    return tops


def _bridge_cells(plane: Plane, p_top: np.ndarray, bridge_m: float) -> int:
    """Add the cells of the plane coordinates ``p_top`` to the plane's extent (in place)
    and close the gaps up to ``bridge_m`` between them and its cells; returns the number of
    cells added."""
    from scipy.ndimage import binary_closing

    own = np.argwhere(plane.occupied)
    p_own = plane.lo + (own + 0.5) * plane.cell_m
    lo = np.minimum(plane.lo, np.floor((p_top.min(0) - plane.lo) / plane.cell_m - 1)
                    * plane.cell_m + plane.lo)  # fmt: skip
    p2 = np.concatenate([p_own, p_top])
    ij = np.floor((p2 - lo) / plane.cell_m).astype(np.int64)
    pad = int(np.ceil(bridge_m / plane.cell_m))
    occ = np.zeros(ij.max(0) + 1 + 2 * pad, bool)
    occ[ij[:, 0] + pad, ij[:, 1] + pad] = True
    before = int(plane.occupied.sum())
    occ = binary_closing(occ, iterations=int(np.ceil(pad / 2))) | occ
    plane.lo, plane.occupied = lo - pad * plane.cell_m, occ
    return int(occ.sum()) - before
