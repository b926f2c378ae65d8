"""The planes of the plane fill, written to the dense workspace (``plane_fill.npz``) for
the pictures (:func:`scenebot.dense.plots.plot_planes`) and for users."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scenebot.dense.planes.geometry import Plane

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
