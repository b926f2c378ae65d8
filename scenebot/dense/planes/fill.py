"""Step 5 of the plane fill, in one view: the holes filled from the planes
(:func:`fill_view`).

With ``fill_rule: bounding_planes`` a hole cell is filled when at least ``min_votes`` of the
found cells (:mod:`~scenebot.dense.planes.labels`), and at least ``min_agreement`` of them,
lie on planes, and each of its pixels takes the boundary plane its ray meets first (a plain
corner between two walls and the floor; with ``fill_planes: any_boundary`` any boundary, so
a plain ceiling above plain walls too); with ``same_plane`` they must all carry the same
plane label. Either way one bounded by something nearer (a plain cabinet face before a
wall) is not filled, because its nearest measured neighbours are the cabinet's edges, off
every plane. Each hole pixel of a filled cell gets the depth where its ray meets the plane
(in front of the camera, inside the plane's extent grown by ``extent_margin_m``; with
``same_plane`` also within the view's depth range, the sparse points' range, which the
floor just before the camera lies nearer than) and the plane's normal, turned towards the
camera.
"""

from __future__ import annotations

import numpy as np

from scenebot.dense.config import PlaneFillConfig
from scenebot.dense.planes.geometry import (
    Plane,
    behind_limit,
    camera_rays,
    image_window,
    in_raster,
)
from scenebot.dense.planes.labels import CellVotes, neighbour_votes, pixel_labels


def fill_view(
    depth: np.ndarray,
    normal: np.ndarray,
    K: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    planes: list[Plane],
    depth_range: tuple[float, float],
    *,
    distance_m: float,
    rel_distance: float,
    cell_px: int,
    max_gap_frac: float,
    min_votes: int,
    min_agreement: float,
    extent_margin_m: float,
    cull_behind: bool,
    bounding_planes: bool,
    max_seen_through: float | None,
    any_boundary: bool,
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

    ``bounding_planes``: the ``bounding_planes`` fill rule (else ``same_plane``);
    ``any_boundary``: with it, a hole's pixel may take any boundary plane its ray meets
    (``fill_planes: any_boundary``), not only its neighbours'.

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
    ray, centre, hits, hits_fill = _cached_plane_hits(
        K, R, t, planes, (h, w), bounding_planes, extent_margin_m, cache
    )
    seen_through: set[int] = set()
    if max_seen_through is not None:  # planes this view sees through are not used in it
        seen_through = _seen_through(
            planes, depth, ray, centre, hits, distance_m, rel_distance, max_seen_through
        )
        for j in seen_through:
            hits[j] = np.inf
            if hits_fill is not None:
                hits_fill[j] = np.inf
    culled = 0
    if cull_behind:
        depth, normal, culled = _cull_behind(depth, normal, hits, distance_m, rel_distance)
        if culled:
            measured = depth > 0
    label = pixel_labels(depth, measured, K, R, t, planes, distance_m, rel_distance)
    cells = neighbour_votes(label, measured, len(planes), cell_px, max_gap_frac)
    out_d, out_n = depth.copy(), normal.copy()
    if bounding_planes:
        cand = _bounding_candidates(cells, planes, min_votes, min_agreement, any_boundary)
        filled = _fill_front(out_d, out_n, measured, cand, hits_fill, centre, R, planes, cell_px)
        return out_d, out_n, filled, culled
    px_label = _same_plane_labels(cells, min_votes, min_agreement, cell_px, (h, w))
    target = ~measured & (px_label >= 0)
    if not target.any():
        return depth, normal, 0, culled
    filled = _fill_same_plane(
        out_d, out_n, target, px_label, ray, hits, centre, R, planes, seen_through,
        depth_range, extent_margin_m, distance_m, rel_distance,
    )  # fmt: skip
    return out_d, out_n, filled, culled


def fill_view_settings(cfg: PlaneFillConfig, first_pass: bool = True) -> dict:
    """The settings of :func:`fill_view` (all but ``cache``) from the config, for the
    first pass over a view or a later one (which culls nothing: the first did)."""
    return {
        "distance_m": cfg.label_distance_m,
        "rel_distance": cfg.label_rel_distance,
        "cell_px": cfg.cell_px,
        "max_gap_frac": cfg.max_gap_frac,
        "min_votes": cfg.min_votes,
        "min_agreement": cfg.min_agreement,
        "extent_margin_m": cfg.extent_margin_m,
        "cull_behind": cfg.cull_behind and first_pass,
        "bounding_planes": cfg.fill_rule == "bounding_planes",
        "max_seen_through": cfg.max_seen_through if cfg.drop_phantoms else None,
        "any_boundary": cfg.fill_planes == "any_boundary",
    }


def _cached_plane_hits(
    K: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    planes: list[Plane],
    shape: tuple[int, int],
    bounding_planes: bool,
    extent_margin_m: float,
    cache: dict | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """:func:`_plane_hits`, computed in the first pass over a view and kept in ``cache``
    (when given) for the later ones; the hits returned are the caller's own copies."""
    if cache is not None and "ray" in cache:  # an earlier pass over the same view
        hits_fill = None if cache["hits_fill"] is None else cache["hits_fill"].copy()
        return cache["ray"], cache["centre"], cache["hits"].copy(), hits_fill
    ray, centre, hits, hits_fill = _plane_hits(
        K, R, t, planes, shape, bounding_planes, extent_margin_m
    )
    if cache is not None:
        cache.update(ray=ray, centre=centre, hits=hits.copy(),
                     hits_fill=None if hits_fill is None else hits_fill.copy())  # fmt: skip
    return ray, centre, hits, hits_fill


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
    ray_cam = camera_rays(uu, vv, K).reshape(-1, 3)
    centre = -R.T @ t
    ray = ray_cam @ R  # world directions with unit z in the camera
    hits = np.full((len(planes), h * w), np.inf)
    hits_fill = np.full((len(planes), h * w), np.inf) if bounding_planes else None
    pixel = np.arange(h * w).reshape(h, w)
    for j, pl in enumerate(planes):
        win = image_window(pl, K, R, t, shape)
        if win is None:  # no ray of the view meets the plane's raster
            continue
        px = pixel[win].reshape(-1)  # only these rays can meet the plane's raster
        ray_w = ray[px]
        denom = ray_w @ pl.normal
        with np.errstate(divide="ignore", invalid="ignore"):
            z = -(centre @ pl.normal + pl.offset) / denom  # z-depth (ray has unit camera z)
        idx = np.flatnonzero(np.isfinite(z) & (z > 0))
        zi = z[idx]
        cells = pl.cells(centre + zi[:, None] * ray_w[idx])  # once for both extents
        if hits_fill is not None:  # where a fill may put this plane: a boundary's extent
            # grown by the margin; an object's face only on its own cells (its edge is the
            # object's)
            okf = np.abs(denom[idx]) > 0.1 * np.linalg.norm(ray_w[idx], axis=1)
            okf[okf] = in_raster(pl.grown(extent_margin_m if pl.boundary else 0.0), cells[okf])
            hits_fill[j, px[idx[okf]]] = zi[okf]
        ok = in_raster(pl.occupied, cells)
        hits[j, px[idx[ok]]] = zi[ok]
    return ray, centre, hits, hits_fill


def _seen_through(
    planes: list[Plane],
    depth: np.ndarray,
    ray: np.ndarray,
    centre: np.ndarray,
    hits: np.ndarray,
    distance_m: float,
    rel_distance: float,
    max_seen_through: float,
) -> set[int]:
    """The object faces (no boundary) this view sees through: more of its measured pixels
    lie behind the face's extent than ``max_seen_through`` times those on it."""
    flat_d = depth.reshape(-1)
    flat_m = (depth > 0).reshape(-1)
    X = centre + flat_d[flat_m, None] * ray[flat_m]
    tol = np.maximum(distance_m, rel_distance * flat_d[flat_m])
    seen_through = set()
    for j, pl in enumerate(planes):
        if pl.boundary:  # nothing is measured past a wall or floor: depth there is wrong
            continue
        n_on = int((np.abs(X @ pl.normal + pl.offset) < tol).sum())
        n_behind = int((hits[j, flat_m] < behind_limit(flat_d[flat_m], distance_m,
                                                       rel_distance)).sum())  # fmt: skip
        if n_behind > max_seen_through * max(n_on, 1):
            seen_through.add(j)
    return seen_through


def _cull_behind(
    depth: np.ndarray, normal: np.ndarray, hits: np.ndarray, distance_m: float,
    rel_distance: float,
) -> tuple[np.ndarray, np.ndarray, int]:  # fmt: skip
    """Measured depth behind a plane's extent (seen through the floor) is an outlier: the
    maps without it (copies, when any is culled) and the number of pixels culled."""
    flat_d = depth.reshape(-1)
    behind = (flat_d > 0) & (hits.min(0) < behind_limit(flat_d, distance_m, rel_distance))
    culled = int(behind.sum())
    if culled:
        depth = depth.copy()
        normal = normal.copy()
        depth.reshape(-1)[behind] = 0
        normal.reshape(-1, 3)[behind] = 0
    return depth, normal, culled


def _camera_normal(plane: Plane, centre: np.ndarray, R: np.ndarray) -> np.ndarray:
    """The plane's normal in the camera frame, facing the camera: n . (centre - x) > 0."""
    return R @ (plane.normal if centre @ plane.normal + plane.offset > 0 else -plane.normal)


def _same_plane_labels(
    cells: CellVotes, min_votes: int, min_agreement: float, cell_px: int,
    shape: tuple[int, int],
) -> np.ndarray:  # fmt: skip
    """(H, W) the plane each pixel's cell is filled with under ``same_plane`` (-1: none):
    the plane most of its nearest measured cells lie on, when they agree enough."""
    h, w = shape
    winner = cells.votes.argmax(0)
    top = cells.votes.max(0)
    vote_ok = cells.agree(top, min_votes, min_agreement)
    # a cell with measured depth on a plane fills its own holes with that plane
    fill_label = np.where(cells.cell_label >= 0, cells.cell_label, np.where(vote_ok, winner, -1))
    fill_label[cells.cell_measured & (cells.cell_label < 0)] = -1
    return np.repeat(np.repeat(fill_label, cell_px, 0), cell_px, 1)[:h, :w]


def _fill_same_plane(
    out_d: np.ndarray,
    out_n: np.ndarray,
    target: np.ndarray,
    px_label: np.ndarray,
    ray: np.ndarray,
    hits: np.ndarray,
    centre: np.ndarray,
    R: np.ndarray,
    planes: list[Plane],
    seen_through: set[int],
    depth_range: tuple[float, float],
    extent_margin_m: float,
    distance_m: float,
    rel_distance: float,
) -> int:
    """Fill the ``target`` pixels (in place) with their label's plane, where its ray meets
    it within the depth range, inside the extent grown by ``extent_margin_m``, not at a
    grazing angle and not behind another plane's extent; returns the number filled."""
    lo, hi = depth_range
    w = out_d.shape[1]
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
        vv, uu = v[m][ok], u[m][ok]
        out_d[vv, uu] = z[ok]
        out_n[vv, uu] = _camera_normal(pl, centre, R)
        filled += int(ok.sum())
    return filled


def _bounding_candidates(
    cells: CellVotes, planes: list[Plane], min_votes: int, min_agreement: float,
    any_boundary: bool,
) -> np.ndarray:  # fmt: skip
    """(P, hc, wc) bool: the planes each hole cell may be filled with under
    ``bounding_planes``.

    A hole cell qualifies when at least ``min_votes`` of its 8 nearest measured cells, and
    ``min_agreement`` of those found, lie on some plane (any plane: a plain wall meets the
    floor, another wall, the ceiling); a plain object before the wall is bounded by its own
    edges, which lie off every plane, and is left empty. Its candidates are the boundary
    planes that bound it (its own measured label included; with ``any_boundary`` every
    boundary plane). An object's face (a plane that is no boundary) is the only candidate
    of the cells it bounds by itself (``min_votes`` and ``min_agreement`` of the found
    cells on it) and of its own measured cells.
    """
    votes, cell_label, cell_measured = cells.votes, cells.cell_label, cells.cell_measured
    boundary = np.array([pl.boundary for pl in planes])
    vote_ok = cells.agree(votes.sum(0), min_votes, min_agreement)
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
    alone = cells.agree(top, min_votes, min_agreement)
    obj = np.where((obj < 0) & alone & ~boundary[winner] & ~cell_measured, winner, obj)
    if (obj >= 0).any():
        cand[:, obj >= 0] = False
        jj, ii, kk = obj[obj >= 0], *np.nonzero(obj >= 0)
        cand[jj, ii, kk] = True
    return cand


def _fill_front(
    out_d: np.ndarray,
    out_n: np.ndarray,
    measured: np.ndarray,
    cand: np.ndarray,
    hits: np.ndarray,
    centre: np.ndarray,
    R: np.ndarray,
    planes: list[Plane],
    cell_px: int,
    edge_px: int = 3,
    edge_rel: float = 0.05,
) -> int:
    """Fill holes bounded by planes with the front-most of those planes (in place).

    Each hole pixel of a cell with candidates (:func:`_bounding_candidates`) takes, among
    them, the one its ray meets first inside the plane's extent (``hits``: where a fill may
    put each plane): where two walls and the floor bound a plain corner, every pixel lands
    on the surface it sees. A pixel within ``edge_px`` of measured depth more than
    ``edge_rel`` nearer or farther than its fill stays empty: beside an object's edge the
    hole may be either side of it.

    Returns:
        The number of pixels filled.
    """
    h, w = out_d.shape
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
        ok &= _away_from_edges(out_d, measured, v, u, zb, edge_px, edge_rel)
    filled = 0
    for j, pl in enumerate(planes):
        m = ok & (best == j)
        if not m.any():
            continue
        out_d[v[m], u[m]] = zb[m]
        out_n[v[m], u[m]] = _camera_normal(pl, centre, R)
        filled += int(m.sum())
    return filled


def _away_from_edges(
    depth: np.ndarray, measured: np.ndarray, v: np.ndarray, u: np.ndarray, z: np.ndarray,
    edge_px: int, edge_rel: float,
) -> np.ndarray:  # fmt: skip
    """Whether the pixels (v, u) see no measured depth within ``edge_px`` that is more
    than ``edge_rel`` nearer or farther than their fill depth ``z``."""
    import cv2

    kernel = np.ones((2 * edge_px + 1, 2 * edge_px + 1), np.uint8)
    d = np.where(measured, depth, 0).astype(np.float32)
    far = cv2.dilate(d, kernel)[v, u]
    near = cv2.erode(np.where(measured, d, np.inf).astype(np.float32), kernel)[v, u]
    return (far <= z * (1 + edge_rel)) & (near >= z * (1 - edge_rel))
