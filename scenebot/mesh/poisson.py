"""Poisson surface of the sparse map (paper IV.B, "Choosing a goal"), ``round_{r}/mesh.ply``.

Normals come from each point's neighbours (PCA over ``normal_knn`` points, open3d), oriented
towards the cameras that observed the point; Poisson surface reconstruction (open3d) follows;
vertices of low Poisson density (far from any point) are trimmed, and the surface is cropped to
the points' bounding box grown by a margin (Poisson closes the surface far outside the data).
"""

from __future__ import annotations

import logging

import numpy as np

from scenebot.artifacts.mesh import MeshError, check_mesh
from scenebot.mesh.config import MeshConfig

log = logging.getLogger(__name__)


def estimate_normals(xyz: np.ndarray, view_dir: np.ndarray, knn: int) -> np.ndarray:
    """Unit normals from neighbouring points, oriented towards the observing cameras.

    Args:
        xyz: (N, 3) points (m).
        view_dir: (N, 3) unit directions from each point towards its cameras (mean).
        knn: neighbours per point.

    Returns:
        (N, 3) unit normals with ``normal . view_dir >= 0``.
    """
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz))
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(knn=min(knn, len(xyz) - 1)))
    n = np.asarray(pcd.normals)
    flip = np.einsum("nd,nd->n", n, view_dir) < 0
    n[flip] *= -1
    return n


def poisson_mesh(
    xyz: np.ndarray,
    normals: np.ndarray,
    depth: int,
    density_quantile: float,
    bbox_margin_m: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Poisson surface through oriented points, trimmed and cropped.

    Args:
        xyz: (N, 3) points (m).
        normals: (N, 3) unit normals.
        depth: Poisson octree depth (``mesh.poisson_depth``).
        density_quantile: vertices below this quantile of the Poisson density are removed
            (``mesh.density_quantile``).
        bbox_margin_m: crop to the points' bounding box grown by this (m;
            ``mesh.bbox_margin_m``).

    Returns:
        vertices (V, 3) float64 (m), faces (F, 3) int64.
    """
    import open3d as o3d

    # n_threads=1: the multi-threaded Poisson of open3d segfaults at random
    # (isl-org/Open3D#6828); one thread is also deterministic.
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz))
    pcd.normals = o3d.utility.Vector3dVector(normals)
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        mesh, dens = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(
            pcd, depth=depth, linear_fit=False, n_threads=1
        )
    dens = np.asarray(dens)
    if len(dens) and density_quantile > 0:
        mesh.remove_vertices_by_mask(dens < np.quantile(dens, density_quantile))
    lo = xyz.min(axis=0) - bbox_margin_m
    hi = xyz.max(axis=0) + bbox_margin_m
    mesh = mesh.crop(o3d.geometry.AxisAlignedBoundingBox(lo, hi))
    mesh.remove_unreferenced_vertices()
    mesh.remove_degenerate_triangles()
    return np.asarray(mesh.vertices, np.float64), np.asarray(mesh.triangles, np.int64)


def build_mesh(
    xyz: np.ndarray,
    view_dir: np.ndarray,
    track_len: np.ndarray,
    cfg: MeshConfig,
    where: str,
    centres: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Mesh of a sparse map.

    Args:
        xyz: (N, 3) 3D points (m).
        view_dir: (N, 3) unit mean directions towards the observing cameras.
        track_len: (N,) observations per point.
        cfg: mesh settings.
        where: round name for error messages.
        centres: (S, 3) camera centres (m): points farther than ``cfg.max_point_range_m``
            from all of them are left out (logged).

    Returns:
        vertices (V, 3), faces (F, 3).

    Raises:
        MeshError: too few points, or an empty/degenerate result.
    """
    keep = track_len >= cfg.min_track_length
    if centres is not None and len(centres):
        from scipy.spatial import cKDTree

        far = cKDTree(np.asarray(centres, float)).query(xyz)[0] > cfg.max_point_range_m
        if far.any():
            log.warning(
                "%s: %d 3D point(s) farther than mesh.max_point_range_m = %g m from every "
                "camera left out of the mesh (farthest %.0f m)",
                where,
                int(far.sum()),
                cfg.max_point_range_m,
                float(np.linalg.norm(xyz[far] - np.median(centres, 0), axis=1).max()),
            )
        keep &= ~far
    if keep.sum() < cfg.min_points:
        raise MeshError(
            f"{where}: only {int(keep.sum())} 3D points with >= {cfg.min_track_length} "
            f"observations (need mesh.min_points = {cfg.min_points}); capture more photos or "
            "lower mesh.min_track_length / mesh.min_points"
        )
    p, d = xyz[keep], view_dir[keep]
    normals = estimate_normals(p, d, cfg.normal_knn)
    V, F = poisson_mesh(p, normals, cfg.poisson_depth, cfg.density_quantile, cfg.bbox_margin_m)
    check_mesh(V, F, where)
    return V, F
