"""The free space of a round, ``freespace.npz`` / ``freespace.json``: the mesh stage writes it
(:mod:`scenebot.mesh.freespace` computes it), the score, goals and tour stages read it.

Files: ``freespace.json`` (polygons in metres, GeoJSON-like ``MultiPolygon`` coordinates with
holes, plus the raster's geometry), ``freespace.npz`` (the raster ``mask`` (ny, nx) uint8, its
``origin`` (x, y of the corner of cell (0, 0), m), ``resolution`` (m) and the cut ``segments``
(M, 2, 2) in metres), and a picture.
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

    def contains(self, xy: np.ndarray) -> np.ndarray:
        """(N,) bool: points (N, 2) (m) in free space (free cell and exact clearance)."""
        j, i, ok = self.cell_of(xy)
        inside = ok & self.mask[j, i]
        clear = point_segment_distance(xy, self.segments) >= self.robot_radius
        return inside & clear

    def new_area_m2(self, previous: FreeSpace, margin_m: float) -> float:
        """Free area (m^2) farther than ``margin_m`` from ``previous``'s free cells: space
        this round's map knows and the previous round's did not (the rasters may differ)."""
        import cv2

        k = max(int(np.ceil(margin_m / previous.resolution)), 0)
        grown = previous.mask.astype(np.uint8)
        if k > 0:
            disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * k + 1, 2 * k + 1))
            grown = cv2.dilate(grown, disk)
        jj, ii = np.nonzero(self.mask)
        centres = self.origin + (np.stack([ii, jj], 1) + 0.5) * self.resolution
        j, i, ok = previous.cell_of(centres)
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

    def save(self, json_path: str | Path, npz_path: str | Path, round_name: str) -> None:
        """Write ``freespace.json`` and ``freespace.npz``."""
        Path(json_path).parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(
            npz_path,
            mask=self.mask.astype(np.uint8),
            origin=self.origin,
            resolution=np.float64(self.resolution),
            segments=self.segments,
            robot_radius=np.float64(self.robot_radius),
            closed=np.bool_(self.closed),
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
