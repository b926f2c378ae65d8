"""A frontier-style goal chooser: the baseline the paper's score is measured against.

Classic frontier exploration (Yamauchi 1997) sends the robot to the boundary between free
space it has seen and free space it has not, nearest first. Here, on the round's free space
(the map's mesh cut by the camera plane, :mod:`scenebot.mesh.freespace`):

* a free cell is *seen* when it lies inside some photo's field of view within
  ``goals.frontier_range_m`` of the camera, with a line of sight through free cells;
* *frontier* cells are seen free cells next to unseen free cells (4-neighbours), where unseen
  pieces smaller than ``goals.frontier_min_area_m2`` do not count;
* goals: from the robot's last position, repeatedly the nearest frontier cell (straight-line
  distance), looking at the unseen cells around it (mean direction of the unseen free cells
  within ``goals.frontier_look_m``); frontier cells within ``goals.nms_radius_m`` of a chosen
  goal are dropped; the next search starts at the chosen goal;
* exploration is complete when no frontier is left.

It uses neither the rendering-quality score nor the photos' content: only where the cameras
stood and looked.
"""

from __future__ import annotations

import numpy as np

from scenebot.artifacts.freespace import FreeSpace


def seen_cells(
    fs: FreeSpace,
    centres: np.ndarray,
    headings: np.ndarray,
    hfov_deg: float,
    range_m: float,
    rays: int = 48,
) -> np.ndarray:
    """Free cells inside some camera's horizontal field of view and range, in line of sight.

    Args:
        fs: the free space (its non-free cells block the view).
        centres: (N, 2) camera centres (m).
        headings: (N,) viewing directions (rad).
        hfov_deg: horizontal field of view (degrees).
        range_m: how far a camera counts as seeing (m).
        rays: rays per camera across the field of view.

    Returns:
        (ny, nx) bool, True = seen free cell.
    """
    import cv2

    ny, nx = fs.mask.shape
    out = np.zeros((ny, nx), np.uint8)
    res = fs.resolution
    half = np.radians(hfov_deg) / 2
    steps = np.arange(0.5, range_m / res + 0.5, 0.5)  # in cells
    for c_xy, h in zip(np.asarray(centres, float), np.asarray(headings, float), strict=True):
        c = (c_xy - fs.origin) / res
        ang = h + np.linspace(-half, half, rays)
        d = np.stack([np.cos(ang), np.sin(ang)], 1)
        q = c[None, None, :] + steps[None, :, None] * d[:, None, :]  # (rays, steps, 2)
        ij = np.floor(q).astype(np.int64)
        inside = (ij[..., 0] >= 0) & (ij[..., 1] >= 0) & (ij[..., 0] < nx) & (ij[..., 1] < ny)
        blocked = ~inside
        blocked[inside] = ~fs.mask[ij[..., 1][inside], ij[..., 0][inside]]
        # the camera's own cell may be marked non-free (clearance): ignore the first half cell
        blocked[:, 0] = False
        hit = blocked.any(axis=1)
        end = np.where(hit, steps[blocked.argmax(axis=1)], steps[-1])
        ends = c + end[:, None] * d
        poly = np.vstack([c[None], ends])
        cv2.fillPoly(out, [np.round(poly - 0.5).astype(np.int32).reshape(-1, 1, 2)], 1)
    return out.astype(bool) & fs.mask


def unseen_cells(fs: FreeSpace, seen: np.ndarray, min_area_m2: float = 0.0) -> np.ndarray:
    """Unseen free cells, without unseen pieces smaller than ``min_area_m2`` (slivers between
    two photos' fields of view are not worth a trip): (ny, nx) bool."""
    import cv2

    unseen = fs.mask & ~seen
    if min_area_m2 <= 0 or not unseen.any():
        return unseen
    _, lab, stats, _ = cv2.connectedComponentsWithStats(unseen.astype(np.uint8), connectivity=4)
    big = stats[:, cv2.CC_STAT_AREA] * fs.resolution**2 >= min_area_m2
    big[0] = False  # background
    return big[lab] & unseen


def next_to(cells: np.ndarray) -> np.ndarray:
    """(ny, nx) bool: the cells with a 4-neighbour in ``cells``."""
    nb = np.zeros_like(cells)
    nb[1:, :] |= cells[:-1, :]
    nb[:-1, :] |= cells[1:, :]
    nb[:, 1:] |= cells[:, :-1]
    nb[:, :-1] |= cells[:, 1:]
    return nb


def frontier_cells(fs: FreeSpace, seen: np.ndarray, min_area_m2: float = 0.0) -> np.ndarray:
    """Seen free cells with an unseen free 4-neighbour (see :func:`unseen_cells`): (ny, nx)."""
    return seen & next_to(unseen_cells(fs, seen, min_area_m2))


def frontier_goals(
    fs: FreeSpace,
    seen: np.ndarray,
    start_xy: np.ndarray,
    k: int,
    spacing_m: float,
    look_m: float,
    min_area_m2: float = 0.0,
) -> list[dict]:
    """Up to ``k`` frontier goals, nearest first from ``start_xy``, each looking at the unseen.

    Returns:
        Goals ``{"x", "y", "theta", "frontier_cells"}`` (m, rad); empty when no frontier is
        left. A goal must pass :meth:`FreeSpace.contains` (clearance from the walls).
    """
    front = frontier_cells(fs, seen, min_area_m2)
    if not front.any():
        return []
    pts = fs.cell_centres(front)
    pts = pts[fs.contains(pts)]
    unseen = fs.cell_centres(unseen_cells(fs, seen, min_area_m2))
    goals: list[dict] = []
    here = np.asarray(start_xy, float)
    alive = np.ones(len(pts), bool)
    while len(goals) < k and alive.any():
        idx = np.flatnonzero(alive)
        j = idx[np.argmin(np.hypot(*(pts[idx] - here).T))]
        p = pts[j]
        near = unseen[np.hypot(*(unseen - p).T) <= look_m]
        v = (near - p).mean(axis=0) if len(near) else np.zeros(2)
        theta = float(np.arctan2(v[1], v[0])) if np.hypot(*v) > 1e-9 else 0.0
        goals.append(
            {"x": float(p[0]), "y": float(p[1]), "theta": theta, "frontier_cells": len(pts)}
        )
        alive &= np.hypot(*(pts - p).T) > spacing_m
        here = p
    return goals


# ------------------------------------------------------------------ open frontiers
# The score's goals (scenebot.goals.select) can only value space the mesh contains: a room
# behind a doorway, seen by no photo, is not in the map, so no candidate lies there and no
# score asks for it. Its doorway shows in the free space as an *open* boundary: free cells
# next to cells the map knows nothing about (FreeSpace.unknown: neither free nor beside a
# wall), where the free space ends because no camera saw across, not because a wall stops
# it. Those are the frontiers the score's goals come after.


def open_boundary(fs: FreeSpace) -> tuple[np.ndarray, np.ndarray]:
    """The free space's open boundary: where it meets space the mesh does not enclose.

    Unknown cells (:meth:`FreeSpace.unknown`) in a piece that reaches the raster's border
    (the raster spans the mesh with a margin, so its border lies outside every cut wall) lie
    beyond an opening of the mesh's outline at least as wide as the clearance band on both
    sides of a wall (about 0.5 m: a doorway, a corridor's mouth); pieces the cut walls
    enclose (the shadow of a sofa no line of sight crossed, a strip along a wall few rays
    reached) lie inside the mapped room, whose surfaces the mesh holds and the score
    values. A free cell on the raster's border has the unknown beyond it.

    Returns:
        ``(boundary, unknown)``: (ny, nx) bool each, the free cells with a 4-neighbour in an
        unknown piece outside the mesh, and those unknown pieces.
    """
    import cv2

    unknown = fs.unknown()
    if not unknown.any():
        return np.zeros_like(fs.mask), unknown
    _, lab = cv2.connectedComponents(unknown.astype(np.uint8), connectivity=8)
    outside = np.zeros(int(lab.max()) + 1, bool)
    outside[np.unique(np.concatenate([lab[0], lab[-1], lab[:, 0], lab[:, -1]]))] = True
    outside[0] = False  # the background (known cells)
    unknown = outside[lab] & unknown
    border = np.zeros_like(fs.mask)
    border[[0, -1], :] = True
    border[:, [0, -1]] = True
    return fs.mask & (next_to(unknown) | border), unknown


def open_frontier_goals(
    fs: FreeSpace,
    min_width_m: float,
    look_m: float,
    visited_xy: np.ndarray,
    k: int,
) -> tuple[list[dict], np.ndarray, np.ndarray]:
    """Goals at the free space's open boundary (:func:`open_boundary`), widest opening first.

    The open boundary's cells within ``look_m`` of a place already visited for a frontier
    (``visited_xy``: earlier rounds' frontier goals, reached or abandoned) are dropped: from
    there a fan of photos looked across and the map still holds nothing beyond (a plain wall
    no feature shows, a window); the next round asks somewhere else or not at all. The rest
    fall into pieces (8-connected); a piece narrower than ``min_width_m`` (its longest
    extent) is a notch in the outline, not an opening. Each piece's goal looks from its free
    cell nearest to the piece's middle that keeps the robot's clearance at the mean direction
    of the unknown cells within ``look_m``, standing back from it by up to half of
    ``look_m`` (the first place back along that line the free space holds); a goal within
    ``look_m`` of a wider opening's goal is left out (two pieces of one outline).

    Returns:
        ``(goals, boundary, unknown)``: up to ``k`` goals ``{"x", "y", "theta",
        "opening_m"}`` (m, rad; ``opening_m`` the piece's extent), and the rasters of
        :func:`open_boundary` (after the visited cells are dropped), for the picture.
    """
    import cv2

    boundary, unknown = open_boundary(fs)
    jj, ii = np.nonzero(boundary)
    xy = fs.cell_centres(boundary)
    visited = np.asarray(visited_xy, float).reshape(-1, 2)
    if len(visited) and len(xy):
        d = np.hypot(xy[:, None, 0] - visited[None, :, 0], xy[:, None, 1] - visited[None, :, 1])
        near = (d <= look_m).any(axis=1)
        boundary[jj[near], ii[near]] = False
    n, lab = cv2.connectedComponents(boundary.astype(np.uint8), connectivity=8)
    unknown_xy = fs.cell_centres(unknown)
    pieces = []
    for c in range(1, n):
        pts = fs.cell_centres(lab == c)
        span = pts.max(axis=0) - pts.min(axis=0) + fs.resolution
        width = float(np.hypot(*span))
        if width < min_width_m:
            continue
        ok = fs.contains(pts)
        if not ok.any():
            continue
        mid = pts.mean(axis=0)
        p = pts[ok][np.argmin(np.hypot(*(pts[ok] - mid).T))]
        near = unknown_xy[np.hypot(*(unknown_xy - p).T) <= look_m]
        v = (near - p).mean(axis=0) if len(near) else np.zeros(2)
        theta = float(np.arctan2(v[1], v[0])) if np.hypot(*v) > 1e-9 else 0.0
        # stand back from the opening by up to half the look distance, where the free space
        # allows: the photos then frame the opening with the known walls beside it (they
        # register by those) instead of a close-up of whatever lies beyond
        u = np.array([np.cos(theta), np.sin(theta)])
        backs = p[None] - np.linspace(0.5 * look_m, 0.0, 5)[:, None] * u[None]
        p = backs[np.argmax(fs.contains(backs))]
        pieces.append({"x": float(p[0]), "y": float(p[1]), "theta": theta,
                       "opening_m": round(width, 3)})  # fmt: skip
    pieces.sort(key=lambda g: -g["opening_m"])
    goals: list[dict] = []
    for g in pieces:  # one goal per opening: pieces of one outline lie side by side
        if len(goals) < k and all(np.hypot(g["x"] - o["x"], g["y"] - o["y"]) > look_m
                                  for o in goals):  # fmt: skip
            goals.append(g)
    return goals, boundary, unknown
