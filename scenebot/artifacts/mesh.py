"""The map's surface, ``round_{r}/mesh.ply``: written by the mesh stage, read (and decimated)
by the score stage; its checks.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


class MeshError(ValueError):
    """The map cannot give a usable mesh; the message says which round and what to change."""


def check_mesh(verts: np.ndarray, faces: np.ndarray, where: str) -> None:
    """Raise :class:`MeshError` when a mesh is empty or degenerate (zero area or volume extent).

    Args:
        verts: (V, 3) vertices (m).
        faces: (F, 3) triangles.
        where: what to name in the message (e.g. ``"round_002 mesh.ply"``).
    """
    hint = (
        "the map of this round has too few or too flat 3D points; capture more photos "
        "(more round-0 exploration), or lower mesh.density_quantile / mesh.poisson_depth"
    )
    if len(faces) == 0 or len(verts) < 3:
        raise MeshError(f"{where}: the mesh is empty; {hint}")
    tri = verts[faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    if not np.isfinite(verts).all():
        raise MeshError(f"{where}: the mesh has non-finite vertices; {hint}")
    if area.sum() < 1e-6:
        raise MeshError(f"{where}: the mesh has zero area (degenerate triangles); {hint}")
    ext = verts.max(axis=0) - verts.min(axis=0)
    if np.sort(ext)[1] < 1e-3:
        raise MeshError(f"{where}: the mesh is degenerate (extent {ext.round(4)} m); {hint}")


def write_mesh(path: str | Path, verts: np.ndarray, faces: np.ndarray) -> None:
    """Write a triangle mesh as binary PLY (open3d)."""
    import open3d as o3d

    m = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(np.asarray(verts, np.float64)),
        o3d.utility.Vector3iVector(np.asarray(faces, np.int32)),
    )
    m.compute_vertex_normals()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    if not o3d.io.write_triangle_mesh(str(path), m):
        raise OSError(f"could not write {path}")


def read_mesh(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read a triangle mesh (PLY/OBJ/...) as vertices (V, 3) float64 and faces (F, 3) int64."""
    import open3d as o3d

    if not Path(path).exists():
        raise FileNotFoundError(f"{path}: no mesh here; run the mesh stage for this round first")
    m = o3d.io.read_triangle_mesh(str(path))
    return np.asarray(m.vertices, np.float64), np.asarray(m.triangles, np.int64)


def decimate(verts: np.ndarray, faces: np.ndarray, max_triangles: int):
    """Quadric decimation to at most ``max_triangles`` (0 or a smaller mesh: unchanged).

    Args:
        verts: (V, 3) vertices (m).
        faces: (F, 3) triangles.
        max_triangles: target triangle count.

    Returns:
        vertices (V', 3), faces (F', 3).
    """
    if max_triangles <= 0 or len(faces) <= max_triangles:
        return verts, faces
    import open3d as o3d

    m = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(np.asarray(verts, np.float64)),
        o3d.utility.Vector3iVector(np.asarray(faces, np.int32)),
    )
    m = m.simplify_quadric_decimation(target_number_of_triangles=int(max_triangles))
    m.remove_unreferenced_vertices()
    return np.asarray(m.vertices, np.float64), np.asarray(m.triangles, np.int64)
