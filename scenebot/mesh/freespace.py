"""Free space: the mesh cut by the camera plane, shrunk by the robot radius (paper IV.B).

The mesh is cut at the configured heights (default only the camera plane z = 0); the cut
segments are drawn into a raster of ``grid_resolution_m`` cells; cells farther than the robot
radius from every segment are free; the connected free regions that hold the map's camera
centres are the free space. A point is *in free space* when its cell is free and its exact
distance to the cut segments is at least the robot radius.

Files: ``freespace.json`` (polygons in metres, GeoJSON-like ``MultiPolygon`` coordinates with
holes, plus the raster's geometry), ``freespace.npz`` (the raster ``mask`` (ny, nx) uint8, its
``origin`` (x, y of the corner of cell (0, 0), m), ``resolution`` (m) and the cut ``segments``
(M, 2, 2) in metres), and a picture.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scenebot.artifacts.freespace import CLEARANCE_CELLS, FreeSpace, FreeSpaceError, wall_raster


def cut_segments(verts: np.ndarray, faces: np.ndarray, z: float) -> np.ndarray:
    """Intersection of a triangle mesh with the horizontal plane at height ``z``.

    Args:
        verts: (V, 3) vertices (m).
        faces: (F, 3) triangles.
        z: plane height (m).

    Returns:
        (M, 2, 2) segments, endpoints (x, y) in metres.
    """
    tri = verts[faces]  # (F, 3, 3)
    s = tri[:, :, 2] - z
    s = np.where(s == 0, 1e-12, s)  # a vertex on the plane counts as above it
    pos = s > 0
    cross = pos.any(axis=1) & (~pos).any(axis=1)
    tri, s, pos = tri[cross], s[cross], pos[cross]
    # the lone vertex (on its own side) and the two edges from it cross the plane
    lone = np.where(pos.sum(axis=1) == 1, np.argmax(pos, axis=1), np.argmin(pos, axis=1))
    idx = np.arange(len(tri))
    a = tri[idx, lone]
    sa = s[idx, lone]
    pts = []
    for k in (1, 2):
        o = (lone + k) % 3
        b = tri[idx, o]
        sb = s[idx, o]
        w = sa / (sa - sb)
        pts.append(a[:, :2] + w[:, None] * (b[:, :2] - a[:, :2]))
    return np.stack(pts, axis=1)


def line_of_sight(
    wall: np.ndarray, xy: np.ndarray, origin: np.ndarray, resolution: float, n_rays: int = 720
) -> np.ndarray:
    """Cells visible in the plane from any of the given positions (union of visibility polygons).

    From each distinct position (rounded to 5 cm) ``n_rays`` rays march in steps of half a cell
    until they reach a wall cell or the raster border; the polygon through the ray ends is
    filled.

    Args:
        wall: (ny, nx) bool wall raster.
        xy: (N, 2) viewpoints (m).
        origin: (2,) raster corner (m).
        resolution: cell size (m).
        n_rays: rays per viewpoint.

    Returns:
        (ny, nx) bool.
    """
    import cv2

    ny, nx = wall.shape
    out = np.zeros((ny, nx), np.uint8)
    pos = np.unique(np.round(np.asarray(xy, np.float64) / 0.05) * 0.05, axis=0)
    ang = np.linspace(0.0, 2 * np.pi, n_rays, endpoint=False)
    d = np.stack([np.cos(ang), np.sin(ang)], 1)
    steps = np.arange(1, int(np.hypot(nx, ny) * 2) + 2) * 0.5  # in cells
    block = 64
    for p in pos:
        c = (p - origin) / resolution  # position in cell units
        end = np.full(n_rays, steps[-1])
        live = np.arange(n_rays)
        for s0 in range(0, len(steps), block):  # march in blocks; finished rays drop out
            st = steps[s0 : s0 + block]
            q = c[None, None, :] + st[None, :, None] * d[live, None, :]  # (rays, steps, 2)
            ij = np.floor(q).astype(np.int64)
            hit = (ij[..., 0] < 0) | (ij[..., 1] < 0) | (ij[..., 0] >= nx) | (ij[..., 1] >= ny)
            inside = ~hit
            hit[inside] = wall[ij[..., 1][inside], ij[..., 0][inside]]
            done = hit.any(axis=1)
            end[live[done]] = st[hit[done].argmax(axis=1)]
            live = live[~done]
            if len(live) == 0:
                break
        ends = c + end[:, None] * d  # the ray end, in cell units
        poly = np.round(ends - 0.5).astype(np.int32)  # cell-centre coordinates for cv2
        cv2.fillPoly(out, [poly.reshape(-1, 1, 2)], 1)
    return out.astype(bool)


def observation_rays(sfm_dir: str | Path, min_track_length: int) -> np.ndarray:
    """The map's lines of sight seen from above: for every observation of a 3D point (track
    of at least ``min_track_length``) the segment from the observing camera's centre to the
    point, in the x-y plane.

    Returns:
        (M, 2, 2) segments (m): [camera xy, point xy].
    """
    import pycolmap

    rec = pycolmap.Reconstruction(str(sfm_dir))
    centres = {i: rec.image(i).projection_center()[:2] for i in rec.reg_image_ids()}
    segs = []
    for pt in rec.points3D.values():
        ids = [el.image_id for el in pt.track.elements if el.image_id in centres]
        if len(ids) < min_track_length:
            continue
        p = np.asarray(pt.xyz[:2], np.float64)
        segs.extend((centres[i], p) for i in ids)
    return np.asarray(segs, np.float64).reshape(-1, 2, 2)


def ray_coverage(
    rays: np.ndarray, shape: tuple[int, int], origin: np.ndarray, resolution: float
) -> np.ndarray:
    """(ny, nx) bool: the raster cells that some segment of ``rays`` (M, 2, 2) (m) crosses,
    closed over one cell (the gaps between neighbouring rays) and opened over one cell (a
    lone ray, an outlier's, crosses no region)."""
    import cv2

    seen = np.zeros(shape, np.uint8)
    if len(rays):
        ij = np.round((rays - origin) / resolution - 0.5).astype(np.int32)  # cell-centre units
        for a, b in ij:
            cv2.line(seen, (int(a[0]), int(a[1])), (int(b[0]), int(b[1])), 1, 1)
    k = np.ones((3, 3), np.uint8)
    seen = cv2.morphologyEx(seen, cv2.MORPH_CLOSE, k)
    return cv2.morphologyEx(seen, cv2.MORPH_OPEN, k).astype(bool)


def compute_freespace(
    verts: np.ndarray,
    faces: np.ndarray,
    cam_xy: np.ndarray,
    robot_radius: float,
    cut_heights: list[float],
    resolution: float,
    where: str,
    rays: np.ndarray | None = None,
) -> FreeSpace:
    """Free space of a mesh around the cameras.

    Args:
        verts: (V, 3) mesh vertices (m).
        faces: (F, 3) triangles.
        cam_xy: (S, 2) camera centres of the map (m).
        robot_radius: clearance (m).
        cut_heights: heights of the cutting planes (m).
        resolution: raster cell size (m).
        where: round name for error messages.
        rays: (M, 2, 2) lines of sight seen from above (:func:`observation_rays`): when given,
            free space is also only where some camera saw across to a point it observed
            (:func:`ray_coverage`): where the mesh has a hole (a plain whiteboard) its
            Poisson surface bulges out of the room, and the cut would show free space there.

    Returns:
        The free space.

    Raises:
        FreeSpaceError: no camera lies in a free region.
    """
    from scipy import ndimage

    segs = np.concatenate([cut_segments(verts, faces, h) for h in cut_heights], axis=0)
    pts = np.concatenate([verts[:, :2], cam_xy.reshape(-1, 2)])
    pad = robot_radius + 3 * resolution
    origin = pts.min(axis=0) - pad
    shape = np.ceil((pts.max(axis=0) + pad - origin) / resolution).astype(int)[::-1]  # (ny, nx)
    if shape.prod() > 4e7:
        raise FreeSpaceError(
            f"{where}: the free-space raster would have {shape.prod():.0f} cells; raise "
            "mesh.grid_resolution_m"
        )
    wall = wall_raster(segs, tuple(shape), origin, resolution)
    dist = ndimage.distance_transform_edt(~wall) * resolution
    # cell centre within robot_radius + half a cell diagonal of a wall cell centre -> blocked
    free = dist > robot_radius + CLEARANCE_CELLS * resolution
    # only space the cameras have looked across: where the map has holes (walls never
    # photographed) the region would otherwise flow around the outside of the mapped walls
    free &= line_of_sight(wall, cam_xy.reshape(-1, 2), origin, resolution)
    if rays is not None:  # and keep the robot's radius from space no camera saw across
        seen = ray_coverage(rays, shape, origin, resolution)
        free &= ndimage.distance_transform_edt(seen) * resolution > robot_radius
    labels, _ = ndimage.label(free)
    cams = np.floor((cam_xy.reshape(-1, 2) - origin) / resolution).astype(int)
    keep = set()
    # a camera closer than the radius to the (noisy) mesh joins the nearest free region within
    # half a radius; farther regions may lie behind a wall
    reach = int(np.ceil(0.5 * robot_radius / resolution)) + 1
    for i, j in cams:
        lab = labels[max(0, j - reach) : j + reach + 1, max(0, i - reach) : i + reach + 1]
        if labels[j, i] > 0:
            keep.add(int(labels[j, i]))
        elif (lab > 0).any():  # camera closer than the radius to a wall: nearest free region
            jj, ii = np.nonzero(lab > 0)
            k = np.argmin((jj - min(j, reach)) ** 2 + (ii - min(i, reach)) ** 2)
            keep.add(int(lab[jj[k], ii[k]]))
    mask = np.isin(labels, sorted(keep)) if keep else np.zeros(shape, bool)
    if not mask.any():
        raise FreeSpaceError(
            f"{where}: the free space is empty: no camera of the map lies in a region at least "
            f"mesh.robot_radius_m = {robot_radius} m from the mesh cut at heights {cut_heights} m; "
            "check the map alignment (cameras on z = 0), lower mesh.robot_radius_m, or lower "
            "mesh.density_quantile so the mesh has fewer spurious surfaces"
        )
    closed = not (mask[0].any() or mask[-1].any() or mask[:, 0].any() or mask[:, -1].any())
    return FreeSpace(mask, origin, float(resolution), segs, float(robot_radius), closed)
