"""The free space of a round, ``freespace.npz`` / ``freespace.json``: the mesh stage writes it
(:mod:`scenebot.mesh.freespace` computes it), the score, goals and tour stages read it.

Files: ``freespace.json`` (polygons in metres, GeoJSON-like ``MultiPolygon`` coordinates with
holes, plus the raster's geometry), ``freespace.npz`` (the raster ``mask`` (ny, nx) uint8, its
``origin`` (x, y of the corner of cell (0, 0), m), ``resolution`` (m) and the cut ``segments``
(M, 2, 2) in metres), and a picture.

With ``robot: photos`` (a person's photos, six degrees of freedom) the mesh stage writes a 3-D
free space too (:class:`FreeVolume`): ``freespace.npz`` then also holds the voxel grid
(``volume_*`` arrays) and ``freespace.json`` a ``volume`` section; the 2-D raster is then the
free voxels' layer at the photos' median camera height, for the readers that work in a plane.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np


class FreeSpaceError(ValueError):
    """No usable free space; the message says which round and what to change."""


def point_segment_distance(p: np.ndarray, seg: np.ndarray, chunk: int = 2048) -> np.ndarray:
    """Distance from each point to the nearest segment.

    Args:
        p: (N, 2) points (m).
        seg: (M, 2, 2) segments (m).
        chunk: points per vectorized block.

    Returns:
        (N,) distances (m); +inf when there are no segments.
    """
    p = np.asarray(p, np.float64).reshape(-1, 2)
    out = np.full(len(p), np.inf)
    if len(seg) == 0:
        return out
    a = seg[:, 0]
    ab = seg[:, 1] - a
    ab2 = np.maximum((ab * ab).sum(axis=1), 1e-18)
    for s in range(0, len(p), chunk):
        q = p[s : s + chunk, None, :] - a[None]  # (n, M, 2)
        t = np.clip((q * ab[None]).sum(-1) / ab2[None], 0.0, 1.0)
        d = q - t[..., None] * ab[None]
        out[s : s + chunk] = np.sqrt((d * d).sum(-1).min(axis=1))
    return out


def wall_raster(
    segments: np.ndarray, shape: tuple[int, int], origin: np.ndarray, resolution: float
) -> np.ndarray:
    """(ny, nx) bool: the cells the cut ``segments`` (M, 2, 2) (m) pass through (sampled every
    half cell along each segment)."""
    wall = np.zeros(shape, bool)
    segs = np.asarray(segments, np.float64).reshape(-1, 2, 2)
    if len(segs):
        L = np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1)
        n = np.maximum(2, np.ceil(L / (0.5 * resolution)).astype(int) + 1)
        rep = np.repeat(np.arange(len(segs)), n)
        t = np.concatenate([np.linspace(0, 1, k) for k in n])
        p = segs[rep, 0] + t[:, None] * (segs[rep, 1] - segs[rep, 0])
        ij = np.floor((p - origin) / resolution).astype(int)
        ok = (ij[:, 0] >= 0) & (ij[:, 1] >= 0) & (ij[:, 0] < shape[1]) & (ij[:, 1] < shape[0])
        wall[ij[ok, 1], ij[ok, 0]] = True
    return wall


CLEARANCE_CELLS = 0.71
"""A cell is free only when its centre lies farther than the robot radius plus this many cells
(half a cell's diagonal) from the centre of every wall cell."""


@dataclass
class FreeSpace:
    """The free space of one round.

    Attributes:
        mask: (ny, nx) bool raster, True = free (row j is y, column i is x).
        origin: (2,) x, y of the outer corner of cell (0, 0) (m).
        resolution: cell size (m).
        segments: (M, 2, 2) cut segments (obstacles) (m).
        robot_radius: clearance kept from the segments (m).
        closed: False when the free region reaches the raster border (the mesh does not
            enclose the cameras at the cut heights).
    """

    mask: np.ndarray
    origin: np.ndarray
    resolution: float
    segments: np.ndarray
    robot_radius: float
    closed: bool = True

    @property
    def area_m2(self) -> float:
        """Free area (m^2)."""
        return float(self.mask.sum()) * self.resolution**2

    def cell_of(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Cell indices (j, i) of points (N, 2) and whether they fall inside the raster."""
        xy = np.asarray(xy, np.float64).reshape(-1, 2)
        ij = np.floor((xy - self.origin) / self.resolution).astype(np.int64)
        i, j = ij[:, 0], ij[:, 1]
        ok = (i >= 0) & (j >= 0) & (i < self.mask.shape[1]) & (j < self.mask.shape[0])
        return np.clip(j, 0, self.mask.shape[0] - 1), np.clip(i, 0, self.mask.shape[1] - 1), ok

    def cell_centres(self, cells: np.ndarray) -> np.ndarray:
        """(N, 2) centres (m) of the True cells of ``cells`` ((ny, nx) bool), row-major."""
        jj, ii = np.nonzero(cells)
        return self.origin + (np.stack([ii, jj], 1) + 0.5) * self.resolution

    def contains(self, xy: np.ndarray) -> np.ndarray:
        """(N,) bool: points (N, 2) (m) in free space (free cell and exact clearance)."""
        j, i, ok = self.cell_of(xy)
        inside = ok & self.mask[j, i]
        clear = point_segment_distance(xy, self.segments) >= self.robot_radius
        return inside & clear

    def unknown(self, margin_cells: float = 1.0) -> np.ndarray:
        """(ny, nx) bool: the cells the map knows nothing about: not free, and farther than
        the clearance kept from the walls (plus ``margin_cells``) from every cut segment,
        so neither wall nor the band beside it. Where the free space ends at such cells no
        wall bounds it: no camera saw across (a doorway's far side, a corridor beyond the
        photos' reach)."""
        from scipy import ndimage

        wall = wall_raster(self.segments, self.mask.shape, self.origin, self.resolution)
        if not wall.any():
            return ~self.mask
        dist = ndimage.distance_transform_edt(~wall) * self.resolution
        band = self.robot_radius + (CLEARANCE_CELLS + margin_cells) * self.resolution
        return ~self.mask & (dist > band)

    def new_area_m2(self, previous: FreeSpace, margin_m: float) -> float:
        """Free area (m^2) farther than ``margin_m`` from ``previous``'s free cells: space
        this round's map knows and the previous round's did not (the rasters may differ)."""
        import cv2

        k = max(int(np.ceil(margin_m / previous.resolution)), 0)
        grown = previous.mask.astype(np.uint8)
        if k > 0:
            disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * k + 1, 2 * k + 1))
            grown = cv2.dilate(grown, disk)
        j, i, ok = previous.cell_of(self.cell_centres(self.mask))
        known = ok & (grown[j, i] > 0)
        return float((~known).sum()) * self.resolution**2

    def polygons(self) -> list[list[list[list[float]]]]:
        """Free-space outlines as MultiPolygon coordinates: polygons of [exterior, *holes] rings
        of [x, y] points (m), exteriors counter-clockwise."""
        import cv2

        m = self.mask.astype(np.uint8)
        contours, hier = cv2.findContours(m, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_SIMPLE)
        polys: list[list[list[list[float]]]] = []
        if hier is None:
            return polys
        hier = hier[0]

        def ring(c: np.ndarray) -> list[list[float]]:
            pts = (c.reshape(-1, 2) + 0.5) * self.resolution + self.origin
            pts = np.vstack([pts, pts[:1]])
            return np.round(pts, 4).tolist()

        for k, c in enumerate(contours):
            if hier[k][3] >= 0:
                continue  # a hole: attached to its parent below
            rings = [ring(c)]
            child = hier[k][2]
            while child >= 0:
                rings.append(ring(contours[child]))
                child = hier[child][0]
            polys.append(rings)
        return polys

    def save(
        self,
        json_path: str | Path,
        npz_path: str | Path,
        round_name: str,
        volume: FreeVolume | None = None,
    ) -> None:
        """Write ``freespace.json`` and ``freespace.npz`` (with ``volume``: the 3-D free space
        of a person's photos as well)."""
        Path(json_path).parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(
            npz_path,
            mask=self.mask.astype(np.uint8),
            origin=self.origin,
            resolution=np.float64(self.resolution),
            segments=self.segments,
            robot_radius=np.float64(self.robot_radius),
            closed=np.bool_(self.closed),
            **({} if volume is None else volume.arrays()),
        )
        doc = {
            "round": round_name,
            "type": "MultiPolygon",
            "units": "m",
            "frame": "robot map frame (z up, camera plane z = 0)",
            "coordinates": self.polygons(),
            "area_m2": round(self.area_m2, 4),
            "robot_radius_m": self.robot_radius,
            "closed": bool(self.closed),
            "raster": {
                "file": Path(npz_path).name,
                "origin_xy_m": self.origin.tolist(),
                "resolution_m": self.resolution,
                "shape_yx": list(self.mask.shape),
            },
        }
        if volume is not None:
            doc["frame"] = "map frame of a person's photos (z up)"
            doc["volume"] = volume.summary()
        Path(json_path).write_text(json.dumps(doc, indent=1))

    @staticmethod
    def load(npz_path: str | Path) -> FreeSpace:
        """Read ``freespace.npz``."""
        if not Path(npz_path).exists():
            raise FileNotFoundError(
                f"{npz_path}: no free space here; run the mesh stage for this round first"
            )
        z = np.load(npz_path)
        return FreeSpace(
            mask=z["mask"].astype(bool),
            origin=z["origin"],
            resolution=float(z["resolution"]),
            segments=z["segments"],
            robot_radius=float(z["robot_radius"]),
            closed=bool(z["closed"]),
        )


@dataclass
class FreeVolume:
    """The 3-D free space of a person's photos: voxels that lines of sight crossed, away from
    the map's surface (computed by :mod:`scenebot.mesh.volume`).

    Attributes:
        free: (nz, ny, nx) bool, True = free (index k is z, j is y, i is x).
        rays: (nz, ny, nx) int32 lines of sight crossing each voxel (count).
        origin: (3,) x, y, z of the outer corner of voxel (0, 0, 0) (m).
        voxel: voxel edge (m).
        clearance: distance (m) kept from the map's points and mesh.
        cameras: (S, 3) the map's camera centres (m).
        min_voxels: fewer free voxels than this is degenerate (``mesh.volume.min_voxels``).
    """

    free: np.ndarray
    rays: np.ndarray
    origin: np.ndarray
    voxel: float
    clearance: float
    cameras: np.ndarray
    min_voxels: int

    @property
    def n_free(self) -> int:
        """Free voxels (count)."""
        return int(self.free.sum())

    @property
    def volume_m3(self) -> float:
        """Free volume (m^3)."""
        return self.n_free * self.voxel**3

    @property
    def camera_height(self) -> float:
        """The photos' median camera height (m): the reference of a person's heights."""
        return float(np.median(self.cameras[:, 2])) if len(self.cameras) else 0.0

    def voxel_of(self, xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Voxel indices (k, j, i) of points (N, 3) (m), clipped, and whether they fall inside
        the grid."""
        xyz = np.asarray(xyz, np.float64).reshape(-1, 3)
        ijk = np.floor((xyz - self.origin) / self.voxel).astype(np.int64)
        shape = np.array(self.free.shape[::-1])  # (nx, ny, nz)
        ok = np.all((ijk >= 0) & (ijk < shape), axis=1)
        ijk = np.clip(ijk, 0, shape - 1)
        return ijk[:, 2], ijk[:, 1], ijk[:, 0], ok

    def contains(self, xyz: np.ndarray) -> np.ndarray:
        """(N,) bool: points (N, 3) (m) in a free voxel."""
        k, j, i, ok = self.voxel_of(xyz)
        return ok & self.free[k, j, i]

    def centres(self, k: np.ndarray, j: np.ndarray, i: np.ndarray) -> np.ndarray:
        """(N, 3) centres (m) of voxels (k, j, i)."""
        return self.origin + (np.stack([i, j, k], 1) + 0.5) * self.voxel

    def layer(self, z: float) -> np.ndarray:
        """(ny, nx) bool: the free voxels of the layer holding height ``z`` (m); none outside
        the grid."""
        k = int(np.floor((z - self.origin[2]) / self.voxel))
        if not 0 <= k < self.free.shape[0]:
            return np.zeros(self.free.shape[1:], bool)
        return self.free[k].copy()

    def degenerate(self) -> str | None:
        """Why this free space says nothing of where a person can stand, or None: too few
        voxels, or no camera of the map in or next to it."""
        if self.n_free < self.min_voxels:
            return (
                f"{self.n_free} free voxels, fewer than mesh.volume.min_voxels = {self.min_voxels}"
            )
        reach = int(np.ceil(self.clearance / self.voxel)) + 1
        k, j, i, ok = self.voxel_of(self.cameras)
        nz, ny, nx = self.free.shape
        for a, b, c, o in zip(k, j, i, ok, strict=True):
            box = self.free[max(a - reach, 0) : min(a + reach + 1, nz),
                            max(b - reach, 0) : min(b + reach + 1, ny),
                            max(c - reach, 0) : min(c + reach + 1, nx)]  # fmt: skip
            if o and box.any():
                return None
        return "no camera of the map lies in or next to the free space"

    def arrays(self) -> dict[str, np.ndarray]:
        """The ``volume_*`` arrays of ``freespace.npz``."""
        return {
            "volume_free": self.free.astype(np.uint8),
            "volume_rays": self.rays.astype(np.int32),
            "volume_origin": np.asarray(self.origin, np.float64),
            "volume_voxel_m": np.float64(self.voxel),
            "volume_clearance_m": np.float64(self.clearance),
            "volume_cameras": np.asarray(self.cameras, np.float64).reshape(-1, 3),
            "volume_min_voxels": np.int64(self.min_voxels),
        }

    def summary(self) -> dict:
        """The ``volume`` section of ``freespace.json``."""
        return {
            "file": "freespace.npz (volume_free: (nz, ny, nx) uint8, 1 = free; volume_rays: "
            "lines of sight per voxel)",
            "origin_xyz_m": np.round(self.origin, 6).tolist(),
            "voxel_m": self.voxel,
            "shape_zyx": list(self.free.shape),
            "free_voxels": self.n_free,
            "volume_m3": round(self.volume_m3, 6),
            "clearance_m": self.clearance,
            "camera_height_m": round(self.camera_height, 6),
            "degenerate": self.degenerate(),
        }

    @staticmethod
    def load(npz_path: str | Path) -> FreeVolume:
        """Read the 3-D free space of ``freespace.npz``.

        Raises:
            FreeSpaceError: the file holds none (the mesh stage ran for a robot).
        """
        if not Path(npz_path).exists():
            raise FileNotFoundError(
                f"{npz_path}: no free space here; run the mesh stage for this round first"
            )
        z = np.load(npz_path)
        if "volume_free" not in z.files:
            raise FreeSpaceError(
                f"{npz_path}: no 3-D free space (the mesh stage ran for a robot); run it "
                "again with robot: photos"
            )
        return FreeVolume(
            free=z["volume_free"].astype(bool),
            rays=z["volume_rays"],
            origin=z["volume_origin"],
            voxel=float(z["volume_voxel_m"]),
            clearance=float(z["volume_clearance_m"]),
            cameras=z["volume_cameras"],
            min_voxels=int(z["volume_min_voxels"]),
        )


def draw_freespace(ax, fs: FreeSpace) -> None:
    """Draw the free space (light), the mesh cut (black lines) into a matplotlib axis."""
    ny, nx = fs.mask.shape
    ext = [fs.origin[0], fs.origin[0] + nx * fs.resolution]
    ext += [fs.origin[1], fs.origin[1] + ny * fs.resolution]
    ax.imshow(fs.mask, origin="lower", extent=ext, cmap="Greys_r", vmin=-1.5, vmax=1.2)
    if len(fs.segments):
        from matplotlib.collections import LineCollection

        ax.add_collection(LineCollection(fs.segments, colors="k", linewidths=0.8))
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
