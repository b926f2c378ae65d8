"""The 3-D free space of a person's photos (``robot: photos``): space the photos saw through is
empty.

A person holds the camera at any height and tilt, so the robot's free space (the mesh cut by
the camera plane, :mod:`scenebot.mesh.freespace`) says little: a photo set of an object or a
facade has no surface at the camera plane to cut, or one that cuts off every camera. Instead:

1. a voxel grid (``mesh.volume.voxel_m``, grown to keep ``mesh.volume.max_voxels``) over the
   map's cameras and its 3D points (those the mesh uses);
2. the lines of sight: for every observation of a 3D point, the segment from the observing
   camera's centre to the point, ending where it first meets the Poisson mesh (a camera does
   not see through a wall: a point behind one is a wrong match, a motif of a repeating
   texture triangulated at the wrong depth, and the space behind the wall is not seen
   through); a voxel that at least ``mesh.volume.min_rays`` of them cross was seen through,
   and is empty; a closing over one voxel fills the gaps between neighbouring lines;
3. voxels whose centre lies within ``mesh.volume.clearance_m`` of a 3D point or a mesh vertex
   are not free (the surface itself, and the hand's room in front of it);
4. the free space is the connected free regions holding a camera (or next to one: a camera
   closer than the clearance to the surface).

A free space of fewer than ``mesh.volume.min_voxels`` voxels, or with no camera in or next to
it, is degenerate: an error, naming the settings.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from scenebot.artifacts.freespace import FreeSpace, FreeSpaceError, FreeVolume
from scenebot.mesh.config import MeshConfig, VolumeConfig

log = logging.getLogger(__name__)


def bulk_cameras(cams: np.ndarray, range_m: float) -> np.ndarray:
    """Which cameras belong to the map's bulk: the largest group of cameras linked through
    neighbours closer than ``range_m`` (m) (a room's cameras are centimetres to metres
    apart; a camera a mapping error put kilometres off is alone). (S,) bool."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    if len(cams) < 2:
        return np.ones(len(cams), bool)
    pairs = cKDTree(cams).query_pairs(range_m, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), (len(cams),) * 2)
    _, label = connected_components(graph, directed=False)
    return label == np.bincount(label).argmax()


def lines_of_sight(
    sfm_dir: str | Path, min_track_length: int, max_range_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """The map's lines of sight: camera centre to observed 3D point, for the points the mesh
    uses (a track of at least ``min_track_length``, within ``max_range_m`` of some camera),
    from the cameras of the map's bulk (:func:`bulk_cameras`; the others are logged).

    Returns:
        (M, 2, 3) segments [camera centre, point] (m), and (S, 3) the bulk's camera centres
        (m).
    """
    import pycolmap

    rec = pycolmap.Reconstruction(str(sfm_dir))
    centres = {i: np.asarray(rec.image(i).projection_center(), float) for i in rec.reg_image_ids()}
    ids = list(centres)
    bulk = bulk_cameras(np.array([centres[i] for i in ids]).reshape(-1, 3), max_range_m)
    if not bulk.all():
        log.warning(
            "%d camera(s) farther than mesh.max_point_range_m = %g m from the map's bulk left "
            "out of the free space: %s",
            int((~bulk).sum()),
            max_range_m,
            ", ".join(rec.image(i).name for i, b in zip(ids, bulk, strict=True) if not b),
        )
        centres = {i: c for (i, c), b in zip(centres.items(), bulk, strict=True) if b}
    cams = np.array(list(centres.values()), float).reshape(-1, 3)
    segs = []
    for pt in rec.points3D.values():
        ids = [el.image_id for el in pt.track.elements if el.image_id in centres]
        if len(ids) < min_track_length:
            continue
        p = np.asarray(pt.xyz, np.float64)
        if min(np.linalg.norm(centres[i] - p) for i in ids) > max_range_m:
            continue
        segs.extend((centres[i], p) for i in ids)
    return np.asarray(segs, np.float64).reshape(-1, 2, 3), cams


def stop_at_surface(
    segs: np.ndarray, verts: np.ndarray, faces: np.ndarray, skip_m: float
) -> tuple[np.ndarray, int]:
    """The lines of sight ending where they first meet the mesh: a camera does not see through
    a surface. The mesh within ``skip_m`` (m) of the camera is passed through (a membrane the
    Poisson reconstruction left next to a camera would otherwise stop all of its lines).

    Args:
        segs: (M, 2, 3) segments [camera centre, point] (m).
        verts: (V, 3) mesh vertices (m).
        faces: (F, 3) triangles.
        skip_m: the mesh this close to the camera does not stop a line (m).

    Returns:
        The segments, each ending at the first surface or at its point, and how many of them
        the mesh stopped more than ``skip_m`` short of their point.
    """
    if not len(segs) or not len(faces):
        return segs, 0
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(np.asarray(verts, np.float32)),
        o3d.core.Tensor(np.asarray(faces, np.uint32)),
    )
    a = segs[:, 0]
    d = segs[:, 1] - a
    length = np.linalg.norm(d, axis=1)
    d = d / np.maximum(length, 1e-12)[:, None]
    start = np.minimum(skip_m, length)
    rays = np.hstack([a + start[:, None] * d, d]).astype(np.float32)
    hit = start + scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy().astype(np.float64)
    end = np.minimum(hit, length)
    out = segs.copy()
    out[:, 1] = a + end[:, None] * d
    return out, int((end < length - skip_m).sum())


def voxel_grid(
    cams: np.ndarray, pts: np.ndarray, cfg: VolumeConfig
) -> tuple[np.ndarray, tuple[int, int, int], float]:
    """The grid over cameras and points, padded by the clearance and two voxels.

    Returns:
        origin (3,) (m), shape (nz, ny, nx), voxel edge (m): ``cfg.voxel_m``, or larger when
        the grid would exceed ``cfg.max_voxels``.
    """
    xyz = np.concatenate([cams.reshape(-1, 3), pts.reshape(-1, 3)])
    voxel = cfg.voxel_m
    for _ in range(8):
        pad = cfg.clearance_m + 2 * voxel
        lo, hi = xyz.min(axis=0) - pad, xyz.max(axis=0) + pad
        n = np.maximum(np.ceil((hi - lo) / voxel).astype(int), 1)
        if n.prod() <= cfg.max_voxels:
            break
        voxel *= 1.02 * (n.prod() / cfg.max_voxels) ** (1 / 3)
    if voxel != cfg.voxel_m:
        log.warning(
            "the free-space grid over %.1f x %.1f x %.1f m would exceed mesh.volume.max_voxels "
            "= %d at mesh.volume.voxel_m = %g m: voxels of %.3f m",
            *(hi - lo), cfg.max_voxels, cfg.voxel_m, voxel,
        )  # fmt: skip
    return lo, (int(n[2]), int(n[1]), int(n[0])), float(voxel)


def count_rays(
    segs: np.ndarray,
    origin: np.ndarray,
    shape: tuple[int, int, int],
    voxel: float,
    chunk: int = 4096,
) -> np.ndarray:
    """How many segments cross each voxel (each segment counts once per voxel).

    Args:
        segs: (M, 2, 3) segments (m), inside the grid.
        origin: (3,) corner of voxel (0, 0, 0) (m).
        shape: (nz, ny, nx).
        voxel: voxel edge (m).
        chunk: segments per vectorized block.

    Returns:
        (nz, ny, nx) int32 counts.
    """
    nz, ny, nx = shape
    counts = np.zeros(nz * ny * nx, np.int64)
    dims = np.array([nx, ny, nz])
    for s in range(0, len(segs), chunk):
        a, b = segs[s : s + chunk, 0], segs[s : s + chunk, 1]
        steps = np.ceil(np.linalg.norm(b - a, axis=1) / (0.5 * voxel)).astype(np.int64) + 1
        ray = np.repeat(np.arange(len(a)), steps)
        first = np.cumsum(steps) - steps
        frac = (np.arange(steps.sum()) - first[ray]) / np.maximum(steps[ray] - 1, 1)
        p = a[ray] + frac[:, None] * (b - a)[ray]
        ijk = np.clip(np.floor((p - origin) / voxel).astype(np.int64), 0, dims - 1)
        lin = (ijk[:, 2] * ny + ijk[:, 1]) * nx + ijk[:, 0]
        # samples of a segment run in order and a voxel is convex: a repeat is the previous one
        new = np.ones(len(lin), bool)
        new[1:] = (lin[1:] != lin[:-1]) | (ray[1:] != ray[:-1])
        counts += np.bincount(lin[new], minlength=counts.size)
    return counts.reshape(shape).astype(np.int32)


def compute_volume(
    segs: np.ndarray,
    cams: np.ndarray,
    surface: np.ndarray,
    cfg: VolumeConfig,
    where: str,
) -> FreeVolume:
    """The 3-D free space of a map (see the module docstring).

    Args:
        segs: (M, 2, 3) lines of sight (m), :func:`lines_of_sight`.
        cams: (S, 3) camera centres (m).
        surface: (P, 3) the map's surface: 3D points and mesh vertices (m).
        cfg: ``mesh.volume``.
        where: round name for error messages.

    Returns:
        The free space.

    Raises:
        FreeSpaceError: degenerate (too few free voxels, no camera in or next to them).
    """
    from scipy import ndimage

    ends = segs[:, 1] if len(segs) else np.zeros((0, 3))
    origin, shape, voxel = voxel_grid(cams, np.concatenate([ends, surface]), cfg)
    rays = count_rays(segs, origin, shape, voxel)
    seen = ndimage.binary_closing(rays >= cfg.min_rays, structure=np.ones((3, 3, 3)))
    solid = np.zeros(shape, bool)
    if len(surface):
        ijk = np.floor((surface - origin) / voxel).astype(np.int64)
        ijk = ijk[np.all((ijk >= 0) & (ijk < np.array(shape[::-1])), axis=1)]
        solid[ijk[:, 2], ijk[:, 1], ijk[:, 0]] = True
    clear = ndimage.distance_transform_edt(~solid) * voxel > cfg.clearance_m
    labels, _ = ndimage.label(seen & clear)
    probe = FreeVolume(labels > 0, rays, origin, voxel, cfg.clearance_m, cams, cfg.min_voxels)
    reach = int(np.ceil(cfg.clearance_m / voxel)) + 1
    keep = set()
    k, j, i, ok = probe.voxel_of(cams)
    for a, b, c in zip(k[ok], j[ok], i[ok], strict=True):
        box = labels[max(a - reach, 0) : a + reach + 1, max(b - reach, 0) : b + reach + 1,
                     max(c - reach, 0) : c + reach + 1]  # fmt: skip
        keep |= set(np.unique(box[box > 0]).tolist())
    free = np.isin(labels, sorted(keep)) if keep else np.zeros(shape, bool)
    vol = FreeVolume(free, rays, origin, voxel, cfg.clearance_m, cams, cfg.min_voxels)
    why = vol.degenerate()
    if why is not None:
        raise FreeSpaceError(
            f"{where}: the 3-D free space of the photos is degenerate: {why} ({len(segs)} "
            f"lines of sight, voxels of {voxel:.3g} m); photograph the scene from more places "
            "(more photos with overlap), or lower mesh.volume.min_rays / "
            "mesh.volume.clearance_m / mesh.volume.voxel_m (mesh.volume.min_voxels says how "
            "much free space is enough)"
        )
    return vol


def person_freespace(
    sfm_dir: str | Path, verts: np.ndarray, faces: np.ndarray, cfg: MeshConfig, where: str
) -> tuple[FreeVolume, FreeSpace, int]:
    """The free space of a person's photos: the 3-D free space, and its layer at the photos'
    median camera height as the 2-D free space (for the readers that work in a plane).

    Args:
        sfm_dir: the round's COLMAP model.
        verts: (V, 3) mesh vertices (m).
        faces: (F, 3) mesh triangles: the lines of sight end at them (:func:`stop_at_surface`).
        cfg: mesh settings (``min_track_length``, ``max_point_range_m``, ``volume``).
        where: round name for error messages.

    Returns:
        The free volume, its layer, and how many lines of sight the mesh stopped short of
        their point.
    """
    segs, cams = lines_of_sight(sfm_dir, cfg.min_track_length, cfg.max_point_range_m)
    pts = np.unique(segs[:, 1], axis=0) if len(segs) else np.zeros((0, 3))
    segs, stopped = stop_at_surface(segs, verts, faces, cfg.volume.clearance_m)
    if stopped:
        log.info(
            "%s: %d of %d lines of sight meet the mesh more than %g m before their point "
            "(a point behind a surface): they end there",
            where, stopped, len(segs), cfg.volume.clearance_m,
        )  # fmt: skip
    if len(verts) and len(cams):  # the mesh around a camera left out of the bulk
        from scipy.spatial import cKDTree

        verts = verts[cKDTree(cams).query(verts)[0] <= cfg.max_point_range_m]
    vol = compute_volume(segs, cams, np.concatenate([pts, verts]), cfg.volume, where)
    mask = vol.layer(vol.camera_height)
    closed = not (mask[0].any() or mask[-1].any() or mask[:, 0].any() or mask[:, -1].any())
    plane = FreeSpace(mask, vol.origin[:2].copy(), vol.voxel, np.zeros((0, 2, 2)),
                      vol.clearance, closed)  # fmt: skip
    return vol, plane, stopped
