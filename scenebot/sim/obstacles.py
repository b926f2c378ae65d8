"""2-D obstacle maps of a scene for collision checks of the robot's footprint.

The geometry between two heights (e.g. floor + 1 cm and the robot's height) is projected onto
the floor and rasterized at fine resolution; a Euclidean distance transform then gives, for
every point, the distance to the nearest obstacle (the clearance) and which obstacle cell it
is. A circular footprint of radius r collides where the clearance is below r.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy import ndimage

from scenebot.scene.mesh import SceneMesh


def _clip_polygon_z(poly: np.ndarray, z: float, keep_above: bool) -> np.ndarray:
    """Sutherland-Hodgman clip of a 3-D polygon (K, 3) against the plane at height z."""
    if len(poly) == 0:
        return poly
    out = []
    s = poly[-1]
    for e in poly:
        e_in = e[2] >= z if keep_above else e[2] <= z
        s_in = s[2] >= z if keep_above else s[2] <= z
        if e_in:
            if not s_in:
                t = (z - s[2]) / (e[2] - s[2])
                out.append(s + t * (e - s))
            out.append(e)
        elif s_in:
            t = (z - s[2]) / (e[2] - s[2])
            out.append(s + t * (e - s))
        s = e
    return np.array(out).reshape(-1, 3)


@dataclass
class ObstacleMap:
    """Clearance to the scene's geometry within a height band, on a fine floor grid.

    Attributes:
        origin: (2,) world xy of the centre of cell (0, 0).
        res: cell size (m).
        occupied: (H, W) bool, True where geometry is inside the band, and everywhere not
            connected to the largest free region (inside solids, outside the room).
        clearance: (H, W) float distance (m) from each cell to the nearest occupied cell.
        nearest: (2, H, W) int row/col index of that nearest occupied cell.
    """

    origin: np.ndarray
    res: float
    occupied: np.ndarray
    clearance: np.ndarray
    nearest: np.ndarray

    @staticmethod
    def build(
        scene: SceneMesh, z_min: float, z_max: float, res: float = 0.005, every_region=False
    ) -> ObstacleMap:
        """Rasterize the geometry between heights ``z_min`` and ``z_max`` (m, absolute).

        ``every_region``: keep every free region (rooms closed off from each other within
        the band, as lintels close doorways high up), not only the largest."""
        lo, hi = scene.bounds
        origin = lo[:2] - 0.1
        shape = np.ceil((hi[:2] + 0.1 - origin) / res).astype(int) + 1
        occ = np.zeros((shape[1], shape[0]), np.uint8)
        tris = scene.vertices[scene.triangles]
        zmin, zmax = tris[:, :, 2].min(1), tris[:, :, 2].max(1)
        sel = np.nonzero((zmax >= z_min) & (zmin <= z_max))[0]
        for i in sel:
            poly = _clip_polygon_z(tris[i], z_min, keep_above=True)
            poly = _clip_polygon_z(poly, z_max, keep_above=False)
            if len(poly) < 2:
                continue
            px = np.round((poly[:, :2] - origin) / res).astype(np.int32)
            cv2.fillPoly(occ, [px], 1)
            cv2.polylines(occ, [px], True, 1, 1)
        # outside the scene's bounding box: not reachable
        border = round(0.1 / res)
        occ[:border, :] = 1
        occ[-border:, :] = 1
        occ[:, :border] = 1
        occ[:, -border:] = 1
        # Free cells not connected to the largest free region are enclosed: the inside of
        # solids (a box whose top is above the band rasterizes as its outline only) or the
        # outside of the room. Nothing can drive there: mark them occupied.
        n, labels = cv2.connectedComponents((occ == 0).astype(np.uint8), connectivity=4)
        if every_region:
            occupied = occ.astype(bool)
        elif n > 1:
            counts = np.bincount(labels[occ == 0].ravel(), minlength=n)
            occupied = labels != int(np.argmax(counts))
        else:
            occupied = occ.astype(bool)
        dist, idx = ndimage.distance_transform_edt(~occupied, return_indices=True)
        return ObstacleMap(origin, res, occupied, dist * res, idx)

    def _cell(self, xy) -> tuple[int, int]:
        c = np.round((np.asarray(xy, float) - self.origin) / self.res).astype(int)
        h, w = self.occupied.shape
        return int(np.clip(c[1], 0, h - 1)), int(np.clip(c[0], 0, w - 1))

    def clearance_at(self, xy) -> float:
        """Distance (m) from the point ``xy`` to the nearest obstacle."""
        r, c = self._cell(xy)
        return float(self.clearance[r, c])

    def nearest_obstacle(self, xy) -> np.ndarray:
        """(2,) world xy of the nearest obstacle cell to ``xy``."""
        r, c = self._cell(xy)
        rr, cc = self.nearest[0, r, c], self.nearest[1, r, c]
        return self.origin + np.array([cc, rr]) * self.res

    def free_for(self, xy, radius: float) -> bool:
        """Whether a disc of ``radius`` m at ``xy`` touches no obstacle."""
        return self.clearance_at(xy) >= radius
