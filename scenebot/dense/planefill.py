"""Plane completion of the depth maps: plain walls, floors and ceilings (a planar prior).

Photometric stereo finds no depth on plain paint: there is nothing to match (the default
office's walls have a texture contrast of about 3 grey levels against a sensor noise of
1.5). Indoor scenes are mostly planes, and the measured depth around a plain region usually
lies on the plane that spans it (a poster on the wall, the wall's edges, the pattern of the
carpet). This step, between depth estimation and fusion:

1. **Planes**: every view's measured (filtered) depth is back-projected and thinned to a
   voxel grid with its stereo normals; planes are peeled off the cloud by oriented RANSAC
   (a point supports a plane only where its normal agrees within ``normal_deg``), largest
   first, while one still holds ``min_plane_share`` of the points. Each plane keeps its
   extent: the cells of an in-plane raster that hold inliers, closed over gaps. Planes that
   the measured depth of the views contradicts are dropped (``drop_phantoms``): those seen
   through (more measured depth behind their extent than on it), those that lie behind
   another plane (a slice beneath the floor from a repeating carpet), and shadows: of two
   parallel planes a few centimetres apart (``shadow_gap_m``), the one fewer views support
   (a circle of photos registered 0.2 degrees off puts its wall a few cm in front of itself).
   The ceiling, which a level camera sees only in its photos' top rows, at grazing angles,
   is too small a share of the cloud for RANSAC: it is found as the highest dense height of
   the points with vertical normals, above every camera, with nothing measured above it
   (``ceiling_min_points``, :func:`find_ceiling`), and it spans the floor's extent.
2. **Extents** (``extent: carved_hull``): the room's boundary planes (walls, floor, ceiling:
   almost nothing measured past them) span the convex hull of their cells, less the cells
   that measured depth is seen through (a doorway). A plain wall then reaches between its
   posters and corners; a box face keeps its own cells (:func:`carved_hulls`). With a
   ceiling, the walls rise to it (``walls_to_ceiling_m``, :func:`span_to_ceiling`: a level
   camera measures the top of a wall only from across the room), and the ceiling reaches
   their top edges (:func:`span_walls`: the floor along a wall is often under furniture).
3. **Labels**: a measured pixel carries the label of the plane it lies on (within
   ``distance_m`` or ``rel_distance`` of its depth), or "off-plane". An object's face that
   this view sees through (more of its measured depth behind the face than on it) is wrong
   in this view and is not used in it.
4. **Votes**: on a grid of ``cell_px`` cells, every cell without measured depth looks along 8
   directions, up to ``max_gap_frac`` of the image width, for the nearest cell with measured
   depth. With ``fill_rule: bounding_planes`` it is filled when at least ``min_votes`` of the
   found cells, and at least ``min_agreement`` of them, lie on planes, and each of its pixels
   takes the boundary plane its ray meets first (a plain corner between two walls and the
   floor; with ``fill_planes: any_boundary`` any boundary, so a plain ceiling above plain
   walls too); with ``same_plane`` they must all carry the same plane label. Either way one
   bounded by something nearer (a plain cabinet face before a wall) is not filled, because
   its nearest measured neighbours are the cabinet's edges, off every plane.
5. **Fill**: each hole pixel of a filled cell gets the depth where its ray meets the plane
   (in front of the camera, inside the plane's extent grown by ``extent_margin_m``; with
   ``same_plane`` also within the view's depth range, the sparse points' range, which the
   floor just before the camera lies nearer than) and the plane's normal, turned towards
   the camera. ``passes`` repeat
   the votes and fill with the fill counted as measured: a plain wall's fill spreads to the
   cells whose neighbours the first pass lacked.
6. **Occlusion**: a filled pixel behind the depth that all views measured, projected into
   this view (``occlusion_min_points`` in its cell), lies behind a surface (a plain object
   the fill spread across) and is emptied again (:func:`occluded_fill`). So is a fill that
   the view's own SfM points contradict (``sparse_veto``): a close object that stereo
   missed, whose features lie in the photo in front of the wall the fill painted there
   (:func:`sparse_contradicted_fill`).

Fusion then needs the usual agreement of ``dense.fusion_min_num_pixels`` views, so a plane
is only fused where several views filled it alike. The measured maps are kept in
``stereo/depth_maps_measured`` for the pictures and for comparison.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

LOG = logging.getLogger(__name__)

#: the 8 search directions (row step, column step)
DIRECTIONS = ((0, 1), (0, -1), (1, 0), (-1, 0), (1, 1), (1, -1), (-1, 1), (-1, -1))


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
            hull (:func:`carved_hulls`), and a fill may reach past its cells by the margin.
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
        return (np.asarray(x) - self.origin) @ self.basis.T

    def inside(self, x: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """(N,) bool: the points' projections fall in the extent (grown by ``margin`` m)."""
        occ = self.occupied
        if margin > 0:
            from scipy.ndimage import binary_dilation

            grow = int(np.ceil(margin / self.cell_m))
            occ = binary_dilation(occ, iterations=grow)
        ij = np.floor((self.to_2d(x) - self.lo) / self.cell_m).astype(np.int64)
        ok = (ij[:, 0] >= 0) & (ij[:, 0] < occ.shape[0]) & (ij[:, 1] >= 0)
        ok &= ij[:, 1] < occ.shape[1]
        out = np.zeros(len(ij), bool)
        out[ok] = occ[ij[ok, 0], ij[ok, 1]]
        return out

    def cell_centres(self) -> tuple[np.ndarray, np.ndarray]:
        """The extent's cells: their (K, 2) raster indices and (K, 3) centres (m)."""
        ij = np.argwhere(self.occupied)
        return ij, self.origin + (self.lo + (ij + 0.5) * self.cell_m) @ self.basis

    @property
    def area_m2(self) -> float:
        return float(self.occupied.sum()) * self.cell_m**2


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


def _fit_plane(x: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares plane through points: unit normal and offset."""
    c = x.mean(0)
    n = np.linalg.svd(x - c, full_matrices=False)[2][-1]
    return n, float(-n @ c)


def _ransac_point_normal(
    pts: np.ndarray,
    nrm: np.ndarray,
    distance_m: float,
    cos_normal: float,
    rng: np.random.Generator,
    hypotheses: int = 512,
    score_points: int = 20000,
) -> tuple[np.ndarray, float, np.ndarray]:
    """The plane through one point along its normal that most other points agree with.

    A point agrees when it lies within ``distance_m`` of the plane and its own normal is
    within ``arccos(cos_normal)`` of the plane's. Hypotheses come from single oriented
    points (Schnabel et al.'s oriented RANSAC); the best is refitted by least squares twice.

    Returns:
        The unit normal, offset and the (N,) inlier mask over ``pts``.
    """
    n_pts = len(pts)
    hyp = rng.choice(n_pts, min(hypotheses, n_pts), replace=False)
    sub = rng.choice(n_pts, min(score_points, n_pts), replace=False)
    hn = nrm[hyp]
    hd = -np.einsum("ij,ij->i", hn, pts[hyp])
    agree = (np.abs(pts[sub] @ hn.T + hd) < distance_m) & (np.abs(nrm[sub] @ hn.T) > cos_normal)
    best = int(agree.sum(0).argmax())
    n, d = hn[best], float(hd[best])
    on = np.zeros(n_pts, bool)
    for _ in range(2):
        on = (np.abs(pts @ n + d) < distance_m) & (np.abs(nrm @ n) > cos_normal)
        if on.sum() < 3:
            break
        n, d = _fit_plane(pts[on])
    on = (np.abs(pts @ n + d) < distance_m) & (np.abs(nrm @ n) > cos_normal)
    return n, d, on


def detect_planes(
    points: np.ndarray,
    distance_m: float = 0.015,
    min_share: float = 0.005,
    max_planes: int = 24,
    seed: int = 0,
    cell_m: float = 0.1,
    min_cell_points: int = 3,
    close_cells: int = 2,
    merge_angle_deg: float = 5.0,
    normals: np.ndarray | None = None,
    normal_deg: float = 30.0,
    snap_deg: float = 0.0,
) -> list[Plane]:
    """Peel planes off a cloud by RANSAC, largest first.

    Without ``normals``, open3d's ``segment_plane`` proposes each plane; with them (the
    stereo's per-pixel normals), oriented RANSAC (:func:`_ransac_point_normal`) does, and a
    point belongs to a plane only where its normal agrees within ``normal_deg``: a phantom
    plane that cuts across several surfaces (a diagonal through box corners, a slice beneath
    the floor) finds no support. Each plane is refitted by least squares to its inliers (and
    takes the points within ``distance_m`` of the refit); a plane within
    ``merge_angle_deg`` and ``2 * distance_m`` of one already found (a noisy floor peeled in
    slices) is merged into it.

    Args:
        points: (N, 3) points (m).
        distance_m: inlier distance of RANSAC.
        min_share: stop when the next plane holds fewer than this share of ``points``.
        max_planes: at most this many planes.
        seed: RANSAC seed.
        cell_m, min_cell_points, close_cells: the extent raster (:func:`plane_extent`).
        merge_angle_deg: planes closer in angle (and offset) are one.
        normals: (N, 3) unit normals of the points, or None.
        normal_deg: largest angle between a point's normal and its plane's.
        snap_deg: planes within this angle (degrees) of horizontal or vertical are made
            exactly so (:func:`_snap_plane`); 0: as fitted.

    Returns:
        The planes with their extents, largest first.
    """
    import open3d as o3d

    o3d.utility.random.seed(seed)
    rng = np.random.default_rng(seed)
    rest = np.asarray(points, np.float64)
    rest_n = None if normals is None else np.asarray(normals, np.float64)
    cos_normal = np.cos(np.radians(normal_deg))
    n_all = len(rest)
    found: list[list[np.ndarray]] = []  # inlier sets
    fits: list[tuple[np.ndarray, float]] = []
    cos_merge = np.cos(np.radians(merge_angle_deg))
    for _ in range(4 * max_planes):
        if len(fits) >= max_planes or len(rest) < max(3, min_share * n_all):
            break
        if rest_n is None:
            pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(rest))
            _, idx = pcd.segment_plane(distance_m, 3, 500)
            if len(idx) < max(3, min_share * n_all):
                break
            n, d = _fit_plane(rest[idx])
            on = np.abs(rest @ n + d) < distance_m
            if on.sum() < 3:
                on[idx] = True
        else:
            n, d, on = _ransac_point_normal(rest, rest_n, distance_m, cos_normal, rng)
            if on.sum() < max(3, min_share * n_all):
                break
        inl = rest[on]
        c = inl.mean(0)
        for k, (nk, dk) in enumerate(fits):
            if abs(n @ nk) > cos_merge and abs(c @ nk + dk) < 2 * distance_m:
                found[k].append(inl)
                fits[k] = _fit_plane(np.concatenate(found[k]))
                break
        else:
            found.append([inl])
            fits.append((n, d))
        rest = rest[~on]
        if rest_n is not None:
            rest_n = rest_n[~on]
    up = _up_direction(found, fits, np.cos(np.radians(10.0))) if snap_deg else None
    planes: list[Plane] = []
    for sets, (n, d) in zip(found, fits, strict=True):
        inl = np.concatenate(sets)
        if up is not None:
            n, d = _snap_plane(n, d, inl, up, snap_deg)
        origin = inl.mean(0)
        e1 = np.cross(n, [0.0, 0.0, 1.0] if abs(n[2]) < 0.9 else [1.0, 0.0, 0.0])
        e1 /= np.linalg.norm(e1)
        basis = np.stack([e1, np.cross(n, e1)])
        lo, occ = plane_extent((inl - origin) @ basis.T, cell_m, min_cell_points, close_cells)
        if occ.any():
            planes.append(Plane(n, d, basis, origin, cell_m, lo, occ, len(inl)))
    planes.sort(key=lambda p: -p.inliers)
    return planes


def _up_direction(
    found: list[list[np.ndarray]], fits: list[tuple[np.ndarray, float]], cos_max: float
) -> np.ndarray | None:
    """The normal of the largest plane within ``arccos(cos_max)`` of the map's z axis (the
    floor of a room), signed upwards; None when there is none."""
    best, up = 0, None
    for sets, (n, _) in zip(found, fits, strict=True):
        size = sum(len(s) for s in sets)
        if abs(n[2]) > cos_max and size > best:
            best, up = size, n * np.sign(n[2])
    return up


def _snap_plane(
    n: np.ndarray, d: float, inliers: np.ndarray, up: np.ndarray, snap_deg: float
) -> tuple[np.ndarray, float]:
    """A plane within ``snap_deg`` of horizontal (normal along ``up``) or of vertical
    (normal perpendicular to it) made exactly so, its offset the median over its inliers.

    Walls stand upright and floors lie flat: a wall fitted 1 degree off over its few
    measured patches is 4 cm off at the top of a 2.6 m wall, which its plane completion
    then repeats over the whole wall.
    """
    s = float(n @ up)
    if abs(s) > np.cos(np.radians(snap_deg)):
        n = up * np.sign(s)
    elif abs(s) < np.sin(np.radians(snap_deg)):
        n = n - s * up
        n = n / np.linalg.norm(n)
    else:
        return n, d
    return n, float(-np.median(inliers @ n))


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
        cell_m, min_cell_points, close_cells: its extent raster (:func:`plane_extent`).
        max_beyond: share of the points around it that may lie above it (outliers).
        above_m: how far above it a point counts as above.
        band_m, peak_ratio: the peak test.

    Returns:
        The ceiling plane (its normal the floor's), or None when there is no floor, no
        height holds enough points, depth was measured above it, or RANSAC found it.
    """
    floors = [p for p in planes if abs(p.normal[2]) > np.cos(np.radians(10.0))]
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
    # the highest height holding min_points vertical-normal points within distance_m, a
    # peak: peak_ratio times as many as the same width holds on average within band_m
    hs = np.sort(h[cand])
    lo_i = np.searchsorted(hs, hs - distance_m, "left")
    hi_i = np.searchsorted(hs, hs + distance_m, "right")
    count = hi_i - lo_i
    around = np.searchsorted(hs, hs + band_m, "right") - np.searchsorted(hs, hs - band_m, "left")
    background = (around - count) * distance_m / max(band_m - distance_m, 1e-9)
    dense = np.flatnonzero((count >= min_points) & (count >= peak_ratio * background))
    if not len(dense):
        return None
    k = dense[-1]
    # the densest height within above_m below the highest dense one: the peak, not its edge
    near = dense[hs[dense] > hs[k] - above_m]
    height = float(hs[near[np.argmax(count[near])]])
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


def span_to_ceiling(wall: Plane, ceiling: Plane, max_rise_m: float = 1.2) -> int:
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
    if abs(float(wall.normal @ up)) > np.sin(np.radians(10.0)):
        return 0  # not a wall
    h_ceiling = -ceiling.offset
    cells, X = wall.cell_centres()
    if not len(cells):
        return 0
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
    if not new:
        return 0
    p2 = wall.to_2d(np.concatenate(new))
    ij = np.floor((p2 - wall.lo) / wall.cell_m).astype(np.int64)
    shift = np.maximum(-ij.min(0), 0)  # grow the raster by whole cells, grid kept
    ij = ij + shift
    shape = np.maximum(np.array(wall.occupied.shape) + shift, ij.max(0) + 1)
    occ = np.zeros(shape, bool)
    occ[
        shift[0] : shift[0] + wall.occupied.shape[0], shift[1] : shift[1] + wall.occupied.shape[1]
    ] = wall.occupied
    before = int(occ.sum())
    occ[ij[:, 0], ij[:, 1]] = True
    wall.lo = wall.lo - shift * wall.cell_m
    wall.occupied = occ
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
    from scipy.ndimage import binary_closing

    normal = ceiling.normal / np.linalg.norm(ceiling.normal)
    side = 1.0  # +1: "past it" is along the normal
    if centres is not None and len(centres):
        side = float(-np.sign(np.median(centres @ ceiling.normal + ceiling.offset))) or 1.0
    tops = []
    for w in walls:
        if abs(float(w.normal @ normal)) > np.sin(np.radians(10.0)):
            continue
        _, X = w.cell_centres()
        near = side * (X @ ceiling.normal + ceiling.offset) > -2 * w.cell_m  # cells at it
        tops.append(X[near])
    if not tops or not sum(len(t) for t in tops):
        return 0
    own = np.argwhere(ceiling.occupied)
    p_own = ceiling.lo + (own + 0.5) * ceiling.cell_m
    p_top = ceiling.to_2d(np.concatenate(tops))
    lo = np.minimum(ceiling.lo, np.floor((p_top.min(0) - ceiling.lo) / ceiling.cell_m - 1)
                    * ceiling.cell_m + ceiling.lo)  # fmt: skip
    p2 = np.concatenate([p_own, p_top])
    ij = np.floor((p2 - lo) / ceiling.cell_m).astype(np.int64)
    pad = int(np.ceil(bridge_m / ceiling.cell_m))
    occ = np.zeros(ij.max(0) + 1 + 2 * pad, bool)
    occ[ij[:, 0] + pad, ij[:, 1] + pad] = True
    before = int(ceiling.occupied.sum())
    occ = binary_closing(occ, iterations=int(np.ceil(pad / 2))) | occ
    ceiling.lo, ceiling.occupied = lo - pad * ceiling.cell_m, occ
    return int(occ.sum()) - before


def backproject(depth: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(H, W) z-depth -> (H, W, 3) world points (COLMAP pixel centres at +0.5)."""
    h, w = depth.shape
    v, u = np.mgrid[0:h, 0:w].astype(np.float64) + 0.5
    x = (u - K[0, 2]) / K[0, 0] * depth
    y = (v - K[1, 2]) / K[1, 1] * depth
    cam = np.stack([x, y, depth.astype(np.float64)], -1)
    return (cam - t) @ R  # R^T (x - t)


def _nearest_labels(cell_label: np.ndarray, measured: np.ndarray, max_steps: int) -> np.ndarray:
    """(8, h, w) label of the nearest measured cell in each direction (-2: none found)."""
    h, w = cell_label.shape
    out = np.full((len(DIRECTIONS), h, w), -2, np.int32)
    rows, cols = np.mgrid[0:h, 0:w]
    for k, (dr, dc) in enumerate(DIRECTIONS):
        found = np.zeros((h, w), bool)
        for s in range(1, max_steps + 1):
            r, c = rows + dr * s, cols + dc * s
            ok = (r >= 0) & (r < h) & (c >= 0) & (c < w) & ~found
            if not ok.any():
                break
            rr, cc = r[ok], c[ok]
            hit = measured[rr, cc]
            sel = np.flatnonzero(ok)[hit]
            out[k].flat[sel] = cell_label[rr[hit], cc[hit]]
            found.flat[sel] = True
    return out


def plane_evidence(
    depth: np.ndarray,
    K: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    planes: list[Plane],
    distance_m: float = 0.02,
    rel_distance: float = 0.01,
    stride: int = 4,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What one view's measured depth (every ``stride``-th pixel) says about the planes.

    Returns:
        ``on`` (P,): measured points on each plane; ``behind`` (P,): measured points behind
        each plane's extent along their ray (a phantom plane floating in the room is seen
        through); ``hidden`` (P, P): points on plane j behind plane k's extent (a phantom
        plane beneath the floor lies behind the floor).
    """
    d = depth[::stride, ::stride]
    vv, uu = np.mgrid[0 : depth.shape[0] : stride, 0 : depth.shape[1] : stride]
    m = d > 0
    z_meas = d[m].astype(np.float64)
    ray = np.stack([(uu[m] + 0.5 - K[0, 2]) / K[0, 0], (vv[m] + 0.5 - K[1, 2]) / K[1, 1],
                    np.ones(m.sum())], -1) @ R  # fmt: skip
    centre = -R.T @ t
    n = len(planes)
    X = centre + z_meas[:, None] * ray
    tol = np.maximum(distance_m, rel_distance * z_meas)
    on = np.zeros((n, len(z_meas)), bool)
    back = np.zeros((n, len(z_meas)), bool)
    for j, pl in enumerate(planes):
        on[j] = np.abs(X @ pl.normal + pl.offset) < tol
        with np.errstate(divide="ignore", invalid="ignore"):
            z = -(centre @ pl.normal + pl.offset) / (ray @ pl.normal)
        cand = np.isfinite(z) & (z > 0) & (z < z_meas * (1 - rel_distance) - 2 * distance_m)
        if cand.any():
            cand[cand] = pl.inside(centre + z[cand, None] * ray[cand])
        back[j] = cand
    hidden = on.astype(np.int64) @ back.T.astype(np.int64)
    np.fill_diagonal(hidden, 0)
    return on.sum(1), back.sum(1), hidden


def carved_hulls(
    planes: list[Plane],
    samples: Iterable[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]],
    distance_m: float = 0.02,
    rel_distance: float = 0.01,
    min_rays: int = 2,
    stride: int = 4,
    max_beyond: float = 0.1,
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

    Returns:
        One (H, W) bool raster per plane, on the plane's own raster grid; the boundary
        planes are marked (``Plane.boundary``).
    """
    import cv2
    from scipy.ndimage import binary_dilation

    hulls, through, on = [], [], []
    beyond = np.zeros(len(planes), np.int64)
    for pl in planes:
        ij = np.argwhere(pl.occupied)[:, ::-1].astype(np.int32)  # (x = column, y = row)
        hull = np.zeros(pl.occupied.shape, np.uint8)
        cv2.fillConvexPoly(hull, cv2.convexHull(ij), 1)
        hulls.append(hull.astype(bool) | pl.occupied)
        through.append(np.zeros(pl.occupied.shape, np.int64))
        on.append(np.zeros(pl.occupied.shape, np.int64))
    for depth, K, R, t in samples:
        d = depth[::stride, ::stride]
        vv, uu = np.mgrid[0 : depth.shape[0] : stride, 0 : depth.shape[1] : stride]
        m = d > 0
        if not m.any():
            continue
        z_meas = d[m].astype(np.float64)
        ray = np.stack([(uu[m] + 0.5 - K[0, 2]) / K[0, 0], (vv[m] + 0.5 - K[1, 2]) / K[1, 1],
                        np.ones(m.sum())], -1) @ R  # fmt: skip
        centre = -R.T @ t
        X = centre + z_meas[:, None] * ray
        tol = np.maximum(distance_m, rel_distance * z_meas)
        for j, pl in enumerate(planes):
            shape = np.array(pl.occupied.shape)
            cell = np.floor((pl.to_2d(X) - pl.lo) / pl.cell_m).astype(np.int64)
            sel = (np.abs(X @ pl.normal + pl.offset) < tol) & np.all(
                (cell >= 0) & (cell < shape), 1
            )
            np.add.at(on[j], (cell[sel, 0], cell[sel, 1]), 1)
            with np.errstate(divide="ignore", invalid="ignore"):
                z = -(centre @ pl.normal + pl.offset) / (ray @ pl.normal)
            cand = np.isfinite(z) & (z > 0) & (z < z_meas * (1 - rel_distance) - 2 * distance_m)
            if not cand.any():
                continue
            cell = np.floor((pl.to_2d(centre + z[cand, None] * ray[cand]) - pl.lo) / pl.cell_m)
            cell = cell.astype(np.int64)
            sel = np.all((cell >= 0) & (cell < shape), 1)
            in_hull = np.zeros(len(cell), bool)
            in_hull[sel] = hulls[j][cell[sel, 0], cell[sel, 1]]
            beyond[j] += int((~in_hull).sum())  # seen past the plane where it is not
            np.add.at(through[j], (cell[in_hull, 0], cell[in_hull, 1]), 1)
    out = []
    for j, (pl, hull, thr, onj) in enumerate(zip(planes, hulls, through, on, strict=True)):
        if beyond[j] > max_beyond * onj.sum():
            out.append(pl.occupied)
            continue
        pl.boundary = True
        carved = binary_dilation((thr >= min_rays) & (thr > onj), np.ones((3, 3), bool))
        out.append(pl.occupied | (hull & ~carved))
    return out


def shadow_planes(
    planes: list[Plane], support: np.ndarray, max_gap_m: float, max_angle_deg: float = 5.0,
    min_overlap: float = 0.3,
) -> dict[int, str]:  # fmt: skip
    """Planes that shadow a plane seen by more views, a few centimetres beside it.

    A handful of views whose poses are slightly off (a turn-in-place circle registered with a
    0.2 degree error between its photos) put the wall they see a few centimetres in front of
    where every other view puts it, and RANSAC finds that shadow as a plane of its own,
    parallel to the wall and as large in points. The wall is the one more views support
    (of two that as many views support, the one with more points).

    Args:
        planes: the planes, with their extents.
        support: (P,) number of views whose measured depth lies on each plane.
        max_gap_m: parallel planes closer than this are one surface seen twice.
        max_angle_deg: planes within this angle are parallel.
        min_overlap: share of the weaker plane's cells inside the stronger one's extent.

    Returns:
        {index: reason} of the shadow planes.
    """
    why: dict[int, str] = {}
    cos_par = np.cos(np.radians(max_angle_deg))
    order = sorted(range(len(planes)), key=lambda j: (-support[j], -planes[j].inliers))
    for a, i in enumerate(order):
        if i in why:
            continue
        pi = planes[i]
        for j in order[a + 1 :]:
            pj = planes[j]
            weaker = support[j] < support[i] or (
                support[j] == support[i] and pj.inliers < pi.inliers
            )  # as many views on both: the one with more points is the surface
            if j in why or not weaker or abs(pi.normal @ pj.normal) < cos_par:
                continue
            gap = abs(pj.origin @ pi.normal + pi.offset)
            if gap > max_gap_m:
                continue
            _, X = pj.cell_centres()
            overlap = float(pi.inside(X).mean()) if len(X) else 0.0
            if overlap >= min_overlap:
                why[j] = (f"shadow of a plane {100 * gap:.1f} cm away ({100 * overlap:.0f}% "
                          f"overlap), seen by {support[j]} views against {support[i]}")  # fmt: skip
    return why


def validate_planes(
    planes: list[Plane], on: np.ndarray, behind: np.ndarray, hidden: np.ndarray,
    max_seen_through: float, max_hidden: float, not_hidden: Iterable[int] = (),
) -> tuple[list[int], dict[int, str]]:  # fmt: skip
    """Planes kept (indices) and why the others were dropped: first those seen through
    (``behind > max_seen_through * on``), then, among the rest, those whose points mostly
    lie behind another kept plane (``hidden > max_hidden * on``), except ``not_hidden``
    (the ceiling: its few points lie at the walls' top edges, where a wall's extent closed
    over a gap hides them)."""
    why: dict[int, str] = {}
    for j in range(len(planes)):
        if behind[j] > max_seen_through * max(on[j], 1):
            why[j] = f"seen through: {behind[j]} measured points behind it, {on[j]} on it"
    kept = [j for j in range(len(planes)) if j not in why]
    for j in list(kept):
        if j in set(not_hidden):
            continue
        others = [k for k in kept if k != j]
        worst = max((hidden[j, k] for k in others), default=0)
        if worst > max_hidden * max(on[j], 1):
            why[j] = f"hidden: {worst} of its {on[j]} points lie behind another plane"
    return [j for j in kept if j not in why], why


def _plane_hits(
    K: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    planes: list[Plane],
    shape: tuple[int, int],
    bounding_planes: bool,
    extent_margin_m: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """Every pixel's ray (world direction with unit camera z), the camera centre, and the
    z-depth where each ray meets each plane's extent (P, H*W; inf: it misses it); with
    ``bounding_planes`` also where a fill may put each plane (a boundary's extent grown by
    ``extent_margin_m``, an object's face only on its own cells, not at grazing angles)."""
    h, w = shape
    vv, uu = np.mgrid[0:h, 0:w]
    ray_cam = np.stack([(uu + 0.5 - K[0, 2]) / K[0, 0], (vv + 0.5 - K[1, 2]) / K[1, 1],
                        np.ones((h, w))], -1).reshape(-1, 3)  # fmt: skip
    centre = -R.T @ t
    ray = ray_cam @ R  # world directions with unit z in the camera
    hits = np.full((len(planes), h * w), np.inf)
    hits_fill = np.full((len(planes), h * w), np.inf) if bounding_planes else None
    for j, pl in enumerate(planes):
        denom = ray @ pl.normal
        with np.errstate(divide="ignore", invalid="ignore"):
            z = -(centre @ pl.normal + pl.offset) / denom  # z-depth (ray has unit camera z)
        ok = np.isfinite(z) & (z > 0)
        if hits_fill is not None:  # where a fill may put this plane: a boundary's extent
            # grown by the margin; an object's face only on its own cells (its edge is the
            # object's)
            okf = ok & (np.abs(denom) > 0.1 * np.linalg.norm(ray, axis=1))
            margin = extent_margin_m if pl.boundary else 0.0
            okf[okf] = pl.inside(centre + z[okf, None] * ray[okf], margin)
            hits_fill[j, okf] = z[okf]
        ok[ok] = pl.inside(centre + z[ok, None] * ray[ok])
        hits[j, ok] = z[ok]
    return ray, centre, hits, hits_fill


def fill_view(
    depth: np.ndarray,
    normal: np.ndarray,
    K: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    planes: list[Plane],
    depth_range: tuple[float, float],
    *,
    distance_m: float = 0.02,
    rel_distance: float = 0.01,
    cell_px: int = 4,
    max_gap_frac: float = 0.5,
    min_votes: int = 2,
    min_agreement: float = 0.6,
    extent_margin_m: float = 0.05,
    cull_behind: bool = True,
    bounding_planes: bool = False,
    max_seen_through: float | None = 1.0,
    any_boundary: bool = False,
    cache: dict | None = None,
) -> tuple[np.ndarray, np.ndarray, int, int]:
    """Fill one view's holes from the planes (see the module docstring).

    With ``cull_behind``, measured depth that lies behind a plane's extent along its ray
    (beyond ``2 * distance_m`` and ``rel_distance``: a match through the floor on a
    repeating carpet) is removed first.

    An object's face (a plane that is no boundary of the room) that this view sees through
    (more of its measured pixels lie behind the face's extent than ``max_seen_through``
    times those on it) is wrong here, whatever the other views say: the camera stands
    where the face's extent was closed over a gap, and sees past it. Such a plane neither
    culls nor fills this view. The room's boundaries (walls, floor) are not checked:
    nothing is measured past them, and depth behind them is an outlier. None: no check.

    ``cache``: a dict kept across the passes over one view; the rays and plane hits are
    computed in the first and reused.

    Returns:
        The depth and normal maps with the filled pixels, the number filled and the number
        of measured pixels culled.
    """
    h, w = depth.shape
    measured = depth > 0
    if not planes or not measured.any():
        return depth, normal, 0, 0
    if cache is not None and "ray" in cache:  # an earlier pass over the same view
        ray, centre = cache["ray"], cache["centre"]
        hits = cache["hits"].copy()
        hits_fill = None if cache["hits_fill"] is None else cache["hits_fill"].copy()
    else:
        ray, centre, hits, hits_fill = _plane_hits(K, R, t, planes, (h, w), bounding_planes,
                                                   extent_margin_m)  # fmt: skip
        if cache is not None:
            cache.update(ray=ray, centre=centre, hits=hits.copy(),
                         hits_fill=None if hits_fill is None else hits_fill.copy())  # fmt: skip
    flat_d = depth.reshape(-1)
    flat_m = measured.reshape(-1)
    seen_through: set[int] = set()
    if max_seen_through is not None:  # planes this view sees through are not used in it
        X = centre + flat_d[flat_m, None] * ray[flat_m]
        tol = np.maximum(distance_m, rel_distance * flat_d[flat_m])
        for j, pl in enumerate(planes):
            if pl.boundary:  # nothing is measured past a wall or floor: depth there is wrong
                continue
            n_on = int((np.abs(X @ pl.normal + pl.offset) < tol).sum())
            n_behind = int((hits[j, flat_m] < flat_d[flat_m] * (1 - rel_distance)
                            - 2 * distance_m).sum())  # fmt: skip
            if n_behind > max_seen_through * max(n_on, 1):
                seen_through.add(j)
                hits[j] = np.inf
                if hits_fill is not None:
                    hits_fill[j] = np.inf
    culled = 0
    if cull_behind:
        # measured depth behind a plane's extent (seen through the floor): an outlier
        behind = flat_m & (hits.min(0) < flat_d * (1 - rel_distance) - 2 * distance_m)
        culled = int(behind.sum())
        if culled:
            depth = depth.copy()
            normal = normal.copy()
            depth.reshape(-1)[behind] = 0
            normal.reshape(-1, 3)[behind] = 0
            measured = depth > 0
    X = backproject(depth, K, R, t)
    label = np.full((h, w), -1, np.int32)  # -1: measured, off every plane
    best = np.full((h, w), np.inf)
    tol = np.maximum(distance_m, rel_distance * depth)
    for j, pl in enumerate(planes):
        dist = np.abs(X @ pl.normal + pl.offset)
        on = measured & (dist < tol) & (dist < best)
        label[on], best[on] = j, dist[on]
    # cells: the most common label among a cell's measured pixels
    hc, wc = -(-h // cell_px), -(-w // cell_px)
    pad = ((0, hc * cell_px - h), (0, wc * cell_px - w))
    lab = np.pad(np.where(measured, label, -3), pad, constant_values=-3)
    lab = lab.reshape(hc, cell_px, wc, cell_px).transpose(0, 2, 1, 3).reshape(hc, wc, -1)
    counts = np.stack([(lab == j).sum(-1) for j in range(-1, len(planes))], -1)
    cell_measured = counts.sum(-1) > 0
    cell_label = np.where(cell_measured, counts.argmax(-1) - 1, -2).astype(np.int32)
    near = _nearest_labels(cell_label, cell_measured, max(1, int(max_gap_frac * wc)))
    found = (near >= -1).sum(0)
    votes = np.stack([(near == j).sum(0) for j in range(len(planes))])
    out_d, out_n = depth.copy(), normal.copy()
    lo, hi = depth_range
    if bounding_planes:
        filled = _fill_front(out_d, out_n, measured, cell_label, cell_measured, votes, found,
                             ray, hits_fill, centre, R, planes, cell_px, min_votes,
                             min_agreement, any_boundary=any_boundary)  # fmt: skip
        return out_d, out_n, filled, culled
    winner = votes.argmax(0)
    top = votes.max(0)
    vote_ok = (top >= min_votes) & (top >= min_agreement * np.maximum(found, 1))
    # a cell with measured depth on a plane fills its own holes with that plane
    fill_label = np.where(cell_label >= 0, cell_label, np.where(vote_ok, winner, -1))
    fill_label[cell_measured & (cell_label < 0)] = -1
    px_label = np.repeat(np.repeat(fill_label, cell_px, 0), cell_px, 1)[:h, :w]
    target = ~measured & (px_label >= 0)
    if not target.any():
        return depth, normal, 0, culled
    v, u = np.nonzero(target)
    flat = v * w + u
    ray, hits = ray[flat], hits[:, flat]
    filled = 0
    for j, pl in enumerate(planes):
        m = px_label[v, u] == j
        if not m.any() or j in seen_through:
            continue
        z = -(centre @ pl.normal + pl.offset) / (ray[m] @ pl.normal)
        ok = np.isfinite(z) & (z > lo) & (z < hi) & (np.abs(ray[m] @ pl.normal) > 0.1)
        pts = centre + z[:, None] * ray[m]
        ok &= pl.inside(pts, extent_margin_m)
        # another plane's extent in front of this one hides it (a floor before a phantom
        # plane beneath it)
        others = np.delete(hits[:, m], j, axis=0)
        if len(others):
            ok &= others.min(0) > z * (1 - rel_distance) - distance_m
        if not ok.any():
            continue
        # normals face the camera: n . (centre - x) > 0
        n_cam = R @ (pl.normal if centre @ pl.normal + pl.offset > 0 else -pl.normal)
        vv, uu = v[m][ok], u[m][ok]
        out_d[vv, uu] = z[ok]
        out_n[vv, uu] = n_cam
        filled += int(ok.sum())
    return out_d, out_n, filled, culled


def _fill_front(
    out_d: np.ndarray,
    out_n: np.ndarray,
    measured: np.ndarray,
    cell_label: np.ndarray,
    cell_measured: np.ndarray,
    votes: np.ndarray,
    found: np.ndarray,
    ray: np.ndarray,
    hits: np.ndarray,
    centre: np.ndarray,
    R: np.ndarray,
    planes: list[Plane],
    cell_px: int,
    min_votes: int,
    min_agreement: float,
    edge_px: int = 3,
    edge_rel: float = 0.05,
    any_boundary: bool = False,
) -> int:
    """Fill holes bounded by planes with the front-most of those planes (in place).

    A hole cell qualifies when at least ``min_votes`` of its 8 nearest measured cells, and
    ``min_agreement`` of those found, lie on some plane (any plane: a plain wall meets the
    floor, another wall, the ceiling); a plain object before the wall is bounded by its own
    edges, which lie off every plane, and is left empty. Each of its pixels
    then takes, among the boundary planes that bound it (its own measured label included),
    the one its ray meets first inside the plane's extent: where two walls and the floor
    bound a plain corner, every pixel lands on the surface it sees. An object's face (a
    plane that is no boundary) fills only the cells it bounds by itself (``min_votes`` and
    ``min_agreement`` of the found cells on it) or its own measured cells. A pixel within
    ``edge_px`` of measured depth more than ``edge_rel`` nearer or farther than its fill
    stays empty: beside an object's edge the hole may be either side of it.

    Returns:
        The number of pixels filled.
    """
    h, w = out_d.shape
    boundary = np.array([pl.boundary for pl in planes])
    on_plane = votes.sum(0)
    vote_ok = (on_plane >= min_votes) & (on_plane >= min_agreement * np.maximum(found, 1))
    vote_ok &= ~(cell_measured & (cell_label < 0))
    if any_boundary:  # any boundary plane the ray meets (a plain ceiling above the walls)
        cand = np.broadcast_to(vote_ok[None] & boundary[:, None, None], votes.shape).copy()
    else:  # only the boundary planes among the neighbours' labels
        cand = (votes > 0) & vote_ok[None] & boundary[:, None, None]
    own = (cell_label >= 0) & boundary[np.maximum(cell_label, 0)]
    if own.any():  # a cell measured on a boundary plane may always fill its holes with it
        jj, ii, kk = cell_label[own], *np.nonzero(own)
        cand[jj, ii, kk] = True
    # an object's face (no boundary) fills only what it bounds alone, as with same_plane:
    # at its edge the hole is more often the background its sources could not see
    top, winner = votes.max(0), votes.argmax(0)
    obj = np.where((cell_label >= 0) & ~boundary[np.maximum(cell_label, 0)], cell_label, -1)
    alone = (top >= min_votes) & (top >= min_agreement * np.maximum(found, 1))
    obj = np.where((obj < 0) & alone & ~boundary[winner] & ~cell_measured, winner, obj)
    if (obj >= 0).any():
        cand[:, obj >= 0] = False
        jj, ii, kk = obj[obj >= 0], *np.nonzero(obj >= 0)
        cand[jj, ii, kk] = True
    target = ~measured & np.repeat(np.repeat(cand.any(0), cell_px, 0), cell_px, 1)[:h, :w]
    if not target.any():
        return 0
    v, u = np.nonzero(target)
    flat = v * w + u
    cand_px = cand[:, v // cell_px, u // cell_px]
    z = np.where(cand_px, hits[:, flat], np.inf)
    best = z.argmin(0)
    zb = z[best, np.arange(len(flat))]
    # not clipped to the view's depth range: that is the sparse points' (the stereo's
    # sampling range), and the floor just before the camera lies nearer than any of them
    ok = np.isfinite(zb)
    if edge_px > 0:  # not beside measured depth off by more than edge_rel: an object's edge
        import cv2

        kernel = np.ones((2 * edge_px + 1, 2 * edge_px + 1), np.uint8)
        d = np.where(measured, out_d, 0).astype(np.float32)
        far = cv2.dilate(d, kernel)[v, u]
        near = cv2.erode(np.where(measured, d, np.inf).astype(np.float32), kernel)[v, u]
        ok &= (far <= zb * (1 + edge_rel)) & (near >= zb * (1 - edge_rel))
    filled = 0
    for j, pl in enumerate(planes):
        m = ok & (best == j)
        if not m.any():
            continue
        n_cam = R @ (pl.normal if centre @ pl.normal + pl.offset > 0 else -pl.normal)
        out_d[v[m], u[m]] = zb[m]
        out_n[v[m], u[m]] = n_cam
        filled += int(m.sum())
    return filled


def occluded_fill(
    depth: np.ndarray,
    filled: np.ndarray,
    K: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    cloud: np.ndarray,
    cell_px: int = 4,
    rel: float = 0.05,
    margin_m: float = 0.04,
    min_points: int = 4,
) -> np.ndarray:
    """Filled pixels that lie behind depth measured by the views together.

    A plain object's face whose edges no view measured well is bounded by the plane fill
    of the wall or floor behind it, and a later pass spreads that fill across the object.
    Other views, from elsewhere, often measured the object's texture. The measured cloud
    of all views (thinned) is projected into this view, and a filled pixel with at least
    ``min_points`` measured points in its ``cell_px`` cell nearer than its fill (by ``rel``
    of the depth and ``margin_m``) is behind a measured surface: the fill is wrong there.

    Returns:
        (H, W) bool: the filled pixels to empty again.
    """
    h, w = depth.shape
    out = np.zeros((h, w), bool)
    if not filled.any() or len(cloud) == 0:
        return out
    xc = cloud @ R.T + t
    z = xc[:, 2]
    ok = z > 1e-3
    u = K[0, 0] * xc[ok, 0] / z[ok] + K[0, 2]
    v = K[1, 1] * xc[ok, 1] / z[ok] + K[1, 2]
    z = z[ok]
    ok = (u >= 0) & (u < w) & (v >= 0) & (v < h)
    if not ok.any():
        return out
    hc, wc = -(-h // cell_px), -(-w // cell_px)
    cell = (v[ok] // cell_px).astype(np.int64) * wc + (u[ok] // cell_px).astype(np.int64)
    z = z[ok]
    order = np.lexsort((z, cell))
    cell, z = cell[order], z[order]
    first = np.flatnonzero(np.r_[True, cell[1:] != cell[:-1]])
    k = first + min_points - 1  # the min_points-th nearest point of each cell
    has = k < np.r_[first[1:], len(cell)]
    near = np.full(hc * wc, np.inf)
    near[cell[first[has]]] = z[k[has]]
    near = near.reshape(hc, wc)
    near_px = np.repeat(np.repeat(near, cell_px, 0), cell_px, 1)[:h, :w]
    return filled & (depth * (1 - rel) - margin_m > near_px)


#: the planes of the plane fill and their extents, in the dense workspace
PLANES_NPZ = "plane_fill.npz"


def save_planes(path: Path, planes: list[Plane], ceiling: Plane | None, centres: np.ndarray):
    """Write the planes (normal, offset, in-plane basis, origin, raster corner and cell,
    extent raster, boundary flag, whether it is the ceiling) and the camera centres to an
    ``.npz`` (keys ``p{k}_*``, ``count``, ``centres``) for the pictures and for users."""
    data: dict[str, np.ndarray] = {"count": np.array(len(planes)), "centres": centres}
    for k, p in enumerate(planes):
        data.update({
            f"p{k}_normal": p.normal, f"p{k}_offset": np.array(p.offset),
            f"p{k}_basis": p.basis, f"p{k}_origin": p.origin, f"p{k}_lo": p.lo,
            f"p{k}_cell_m": np.array(p.cell_m), f"p{k}_occupied": p.occupied,
            f"p{k}_inliers": np.array(p.inliers), f"p{k}_boundary": np.array(p.boundary),
            f"p{k}_ceiling": np.array(p is ceiling),
        })  # fmt: skip
    np.savez_compressed(path, **data)


def load_planes(path: Path) -> tuple[list[tuple[Plane, bool]], np.ndarray]:
    """The planes of :func:`save_planes` (with their ceiling flag) and camera centres."""
    z = np.load(path)
    out = []
    for k in range(int(z["count"])):
        g = {n: z[f"p{k}_{n}"] for n in ("normal", "offset", "basis", "origin", "lo",
                                         "cell_m", "occupied", "inliers", "boundary")}  # fmt: skip
        pl = Plane(g["normal"], float(g["offset"]), g["basis"], g["origin"], float(g["cell_m"]),
                   g["lo"], g["occupied"], int(g["inliers"]), bool(g["boundary"]))  # fmt: skip
        out.append((pl, bool(z[f"p{k}_ceiling"])))
    return out, z["centres"]


def sparse_observations(sparse_dir: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per image name, the SfM points it observes: pixel positions (N, 2) as fractions of
    the image's width and height, and their depths along its optical axis (N,), from the
    dense workspace's undistorted model."""
    import pycolmap

    rec = pycolmap.Reconstruction(str(sparse_dir))
    out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for iid in rec.reg_image_ids():
        im = rec.image(iid)
        obs = [(p.xy, p.point3D_id) for p in im.points2D if p.has_point3D()]
        if not obs:
            out[im.name] = (np.zeros((0, 2)), np.zeros(0))
            continue
        cam = rec.camera(im.camera_id)
        xy = np.array([o[0] for o in obs], np.float64) / [cam.width, cam.height]
        X = np.array([rec.point3D(o[1]).xyz for o in obs], np.float64)
        out[im.name] = (xy, (im.cam_from_world() * X)[:, 2])
    return out


def sparse_contradicted_fill(
    depth: np.ndarray,
    filled: np.ndarray,
    uv: np.ndarray,
    z: np.ndarray,
    rel: float = 0.05,
    margin_m: float = 0.03,
    max_edge_px: float = 120.0,
) -> np.ndarray:
    """Filled pixels that the view's own SfM points contradict.

    The SfM points a photo observes are features matched and triangulated across several
    photos: where the photo shows a close object that multi-view stereo missed (a box,
    a bookcase seen from nearby, whose source views did not see it), the plane fill paints
    the wall behind it, yet the object's features lie in the photo, in front of that fill.
    The points are triangulated in the image (Delaunay); each is *contradicted* when it
    lies on a filled pixel, nearer or farther than the fill by more than ``rel`` of the
    depth and ``margin_m``. A triangle whose three corners are contradicted, with no edge
    longer than ``max_edge_px``, covers a surface that is not the filled plane: its filled
    pixels are returned (and the filled pixels within 3 px of a contradicted point).

    Args:
        depth: (H, W) the filled depth map.
        filled: (H, W) bool: which of its pixels the plane fill set.
        uv: (N, 2) pixel positions of the view's SfM observations (x right, y down; pixel
            centres at +0.5, COLMAP's convention).
        z: (N,) their depths.

    Returns:
        (H, W) bool: the filled pixels to empty again.
    """
    import cv2
    from scipy.spatial import Delaunay, QhullError

    h, w = depth.shape
    out = np.zeros((h, w), np.uint8)
    if not filled.any() or len(z) == 0:
        return out.astype(bool)
    u = np.clip(uv[:, 0].astype(np.int64), 0, w - 1)
    v = np.clip(uv[:, 1].astype(np.int64), 0, h - 1)
    d = depth[v, u]
    bad = filled[v, u] & (d > 0) & (np.abs(z - d) > rel * d + margin_m)
    for k in np.flatnonzero(bad):  # the point's own neighbourhood
        cv2.circle(out, (int(uv[k, 0]), int(uv[k, 1])), 3, 1, -1)
    if bad.sum() >= 3:
        try:
            tri = Delaunay(uv).simplices
        except QhullError:  # degenerate (collinear) points
            tri = np.zeros((0, 3), np.int64)
        corners = uv[tri[bad[tri].all(1)]]
        edge = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(1, initial=0.0)
        for c in corners[edge <= max_edge_px]:
            cv2.fillConvexPoly(out, np.round(c - 0.5).astype(np.int32), 1)
    return out.astype(bool) & filled


def plane_fill(
    dense_dir: Path,
    views: list,
    cfg,
    progress: bool = True,
) -> dict:
    """Fill every view's geometric depth and normal maps from the scene's planes.

    Args:
        dense_dir: the dense workspace (``stereo/depth_maps/*.geometric.bin`` filtered).
        views: ``(name, K, R, t, depth_range)`` per view.
        cfg: :class:`~scenebot.dense.config.PlaneFillConfig`.
        progress: show a progress bar.

    Returns:
        Stats: planes (normal, offset, inliers, extent area), pixels measured and filled per
        view, seconds. The measured maps are moved to ``stereo/depth_maps_measured`` (and
        ``normal_maps_measured``) first; a second run starts again from them.
    """
    import shutil
    import time

    from tqdm import tqdm

    from scenebot.dense import workspace as ws
    from scenebot.dense.colmap_io import read_array, write_array

    t0 = time.perf_counter()
    dense_dir = Path(dense_dir)
    kept = {k: dense_dir / "stereo" / f"{k}_maps_measured" for k in ("depth", "normal")}
    for k, folder in kept.items():
        folder.mkdir(parents=True, exist_ok=True)
        for name, *_ in views:
            src = ws.map_path(dense_dir, k, name, "geometric")
            dst = folder / src.name
            if not dst.is_file():
                shutil.copy2(src, dst)

    def measured(name: str) -> tuple[np.ndarray, np.ndarray]:
        fname = ws.map_path(dense_dir, "depth", name, "geometric").name
        return read_array(kept["depth"] / fname), read_array(kept["normal"] / fname)

    centres = np.array([-R.T @ t for _, _, R, t, _ in views])
    # the planes, from every view's measured depth thinned to a voxel grid
    rng = np.random.default_rng(cfg.seed)
    pts, nrms = [], []
    for name, K, R, t, _ in views:
        d, nm = measured(name)
        ok = (d > 0) & (np.linalg.norm(nm, axis=-1) > 0.5)
        X, N = backproject(d, K, R, t)[ok], nm[ok].astype(np.float64) @ R  # world normals
        if len(X) > cfg.points_per_view:
            pick = rng.choice(len(X), cfg.points_per_view, replace=False)
            X, N = X[pick], N[pick]
        pts.append(X)
        nrms.append(N / np.linalg.norm(N, axis=1, keepdims=True))
    cloud = np.concatenate(pts) if pts else np.zeros((0, 3))
    cloud_n = np.concatenate(nrms) if nrms else np.zeros((0, 3))
    if len(cloud):
        keys = np.floor(cloud / cfg.voxel_m).astype(np.int64)
        _, first = np.unique(keys, axis=0, return_index=True)
        cloud, cloud_n = cloud[first], cloud_n[first]
    planes = detect_planes(
        cloud, cfg.ransac_distance_m, cfg.min_plane_share, cfg.max_planes, cfg.seed,
        cfg.extent_cell_m, cfg.extent_min_points, cfg.extent_close_cells, cfg.merge_angle_deg,
        normals=cloud_n if cfg.normal_deg is not None else None,
        normal_deg=cfg.normal_deg or 90.0, snap_deg=cfg.snap_deg,
    )  # fmt: skip
    ceiling = None
    if cfg.ceiling_min_points and planes:
        ceiling = find_ceiling(
            cloud, cloud_n, planes, centres, cfg.ransac_distance_m, cfg.normal_deg or 30.0,
            cfg.ceiling_min_points, cfg.extent_cell_m, cfg.extent_min_points,
            cfg.extent_close_cells,
        )  # fmt: skip
        if ceiling is not None:
            LOG.info("dense: ceiling at %.3f m along %s from %d points", -ceiling.offset,
                     np.round(ceiling.normal, 3).tolist(), ceiling.inliers)  # fmt: skip
            planes.append(ceiling)
    dropped: dict[int, str] = {}
    if cfg.drop_phantoms and planes:
        on = np.zeros(len(planes), np.int64)
        behind = np.zeros(len(planes), np.int64)
        hidden = np.zeros((len(planes), len(planes)), np.int64)
        support = np.zeros(len(planes), np.int64)
        step = max(1, len(views) // 40)
        for k, (name, K, R, t, _) in enumerate(views):
            a, b, c = plane_evidence(measured(name)[0], K, R, t, planes, cfg.label_distance_m,
                                     cfg.label_rel_distance)  # fmt: skip
            support += a >= cfg.support_min_points
            if k % step == 0:
                on, behind, hidden = on + a, behind + b, hidden + c
        keep, dropped = validate_planes(
            planes, on, behind, hidden, cfg.max_seen_through, cfg.max_hidden,
            not_hidden=[j for j, p in enumerate(planes) if p is ceiling],
        )  # fmt: skip
        for j, why in dropped.items():
            LOG.info("dense: plane %d (normal %s) dropped, %s", j,
                     np.round(planes[j].normal, 2).tolist(), why)  # fmt: skip
        dropped = {j: f"normal {np.round(planes[j].normal, 3).tolist()}, offset "
                   f"{planes[j].offset:.3f}: {w}" for j, w in dropped.items()}  # fmt: skip
        planes, support = [planes[j] for j in keep], support[keep]
    if cfg.extent == "carved_hull" and planes:
        samples = ((measured(name)[0], K, R, t) for name, K, R, t, _ in views)  # one at a time
        for pl, ext in zip(planes, carved_hulls(planes, samples, cfg.label_distance_m,
                                                cfg.label_rel_distance, cfg.carve_min_rays),
                           strict=True):  # fmt: skip
            pl.occupied = ext
        # the room's boundary planes other than the ceiling (span_walls keeps the upright ones)
        walls = [p for p in planes if p is not ceiling and p.boundary]
        if cfg.floor_to_walls:
            up = np.array([0.0, 0.0, 1.0])  # the map's z axis (sfm: robot frame, z up)
            level = [p for p in walls if abs(p.normal @ up) > np.cos(np.radians(10.0))]
            if level:  # the floor: the largest level boundary plane below the cameras
                floor = max(level, key=lambda p: p.inliers)
                if np.median(centres @ floor.normal + floor.offset) * (floor.normal @ up) > 0:
                    span_walls(floor, walls, centres=centres)
        if ceiling is not None and any(p is ceiling for p in planes) and ceiling.boundary:
            level = [p for p in walls if abs(p.normal @ ceiling.normal) > 0.999]
            if level:  # the floor: the largest boundary plane parallel to the ceiling
                span_floor(ceiling, max(level, key=lambda p: p.inliers))
            if cfg.walls_to_ceiling_m > 0:
                for p in walls:
                    span_to_ceiling(p, ceiling, cfg.walls_to_ceiling_m)
                span_walls(ceiling, walls)
    if cfg.drop_phantoms and cfg.shadow_gap_m > 0 and planes:
        shadows = shadow_planes(planes, support, cfg.shadow_gap_m, cfg.merge_angle_deg)
        for j, why in shadows.items():
            LOG.info("dense: plane %d (normal %s) dropped, %s", j,
                     np.round(planes[j].normal, 2).tolist(), why)  # fmt: skip
            dropped[len(dropped) + 1000 + j] = (
                f"normal {np.round(planes[j].normal, 3).tolist()}, offset "
                f"{planes[j].offset:.3f}: {why}"
            )
        planes = [p for j, p in enumerate(planes) if j not in shadows]
    LOG.info("dense: %d planes in %d voxel points", len(planes), len(cloud))
    save_planes(dense_dir / PLANES_NPZ, planes, ceiling, centres)
    observed: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    if cfg.sparse_veto and (dense_dir / "sparse").is_dir():
        observed = sparse_observations(dense_dir / "sparse")
    per_view = []
    total_px = total_measured = total_filled = total_culled = total_vetoed = 0
    for name, K, R, t, rng_d in tqdm(views, desc="plane fill", unit="view", disable=not progress):
        d, n = measured(name)
        fd, fn, filled, culled = d, n, 0, 0
        cache: dict = {}
        for k in range(cfg.passes):  # a later pass counts the fill as measured: it spreads
            fd, fn, more, cut = fill_view(
                fd, fn, K, R, t, planes, rng_d,
                distance_m=cfg.label_distance_m, rel_distance=cfg.label_rel_distance,
                cell_px=cfg.cell_px, max_gap_frac=cfg.max_gap_frac, min_votes=cfg.min_votes,
                min_agreement=cfg.min_agreement, extent_margin_m=cfg.extent_margin_m,
                cull_behind=cfg.cull_behind and k == 0,
                bounding_planes=cfg.fill_rule == "bounding_planes",
                max_seen_through=cfg.max_seen_through if cfg.drop_phantoms else None,
                any_boundary=cfg.fill_planes == "any_boundary", cache=cache,
            )  # fmt: skip
            filled, culled = filled + more, culled + cut
            if not more:
                break
        if cfg.occlusion_min_points and filled:
            bad = occluded_fill(fd, (fd > 0) & ~(d > 0), K, R, t, cloud, cfg.cell_px,
                                min_points=cfg.occlusion_min_points)  # fmt: skip
            fd[bad], fn[bad] = 0, 0
            filled -= int(bad.sum())
        vetoed = 0
        if filled and name in observed:
            uv_obs, z_obs = observed[name]
            uv_obs = uv_obs * fd.shape[::-1]
            bad = sparse_contradicted_fill(fd, (fd > 0) & ~(d > 0), uv_obs, z_obs,
                                           max_edge_px=cfg.sparse_veto_max_edge_px)  # fmt: skip
            fd[bad], fn[bad] = 0, 0
            vetoed = int(bad.sum())
            filled -= vetoed
        total_vetoed += vetoed
        write_array(ws.map_path(dense_dir, "depth", name, "geometric"), fd)
        write_array(ws.map_path(dense_dir, "normal", name, "geometric"), fn)
        n_meas = int((d > 0).sum())
        per_view.append({"name": name, "measured": n_meas / d.size, "filled": filled / d.size,
                         "culled": culled / d.size, "vetoed": vetoed / d.size})  # fmt: skip
        total_culled += culled
        total_px += d.size
        total_measured += n_meas
        total_filled += filled
    planes_out = []
    for p in planes:
        planes_out.append({"normal": p.normal.round(4).tolist(), "offset": round(p.offset, 4),
                           "inliers": p.inliers, "area_m2": round(p.area_m2, 3)})  # fmt: skip
    return {
        "planes": planes_out,
        "voxel_points": len(cloud),
        "planes_dropped": list(dropped.values()),
        "measured_fraction": total_measured / max(total_px, 1),
        "filled_fraction": total_filled / max(total_px, 1),
        "culled_fraction": total_culled / max(total_px, 1),
        "vetoed_fraction": total_vetoed / max(total_px, 1),
        "views": per_view,
        "seconds": time.perf_counter() - t0,
    }
