"""The dense stage: sparse map + photos -> COLMAP dense workspace, depth maps, fused cloud.

Entry point :func:`run`. Writes under ``outputs.dense_dir`` (``results/{scene}/final/dense``):

* the COLMAP dense workspace (``images/``, ``sparse/``, ``stereo/``), depth and normal maps in
  COLMAP format (``*.photometric.bin`` unfiltered, ``*.geometric.bin`` after the geometric
  pass and the filter; pycolmap's fusion reads the latter),
* ``fused.ply`` (+ ``fused.ply.vis``) from ``pycolmap.stereo_fusion`` (runs on CPU),
* optionally ``meshed-poisson.ply``,
* ``dense_summary.json`` (backend, per-view sources, depth ranges, coverage, timings),
* with ``plots``: ``fused_views.png``, ``depth_normal_mosaic.png`` and, with the plane
  fill, ``planes.png`` (its planes from above; the planes themselves in ``plane_fill.npz``).

Where taichi runs on the CPU, each step's views (photometric pass, geometric pass, filter,
plane fill: :mod:`scenebot.dense.passes`) are spread over ``dense.num_threads`` worker
processes (:mod:`scenebot.dense.parallel`); on a GPU the stage is one process.
"""

from __future__ import annotations

import json
import logging
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pycolmap

from scenebot.dense import passes
from scenebot.dense import workspace as ws
from scenebot.dense.colmap_cuda import run_patch_match
from scenebot.dense.config import DenseConfig
from scenebot.dense.parallel import ViewPool, one_blas_thread, worker_count
from scenebot.dense.views import ViewPlan, select_views
from scenebot.taichi_setup import init_taichi, taichi_arch

LOG = logging.getLogger(__name__)


@dataclass
class DenseInputs:
    """Inputs of the dense stage.

    Attributes:
        sparse_dir: COLMAP binary model of the last round (``results/{scene}/round_{r}/sfm``).
        image_dir: folder holding every registered photo under its model name.
    """

    sparse_dir: Path
    image_dir: Path


@dataclass
class DenseOutputs:
    """Outputs of the dense stage.

    Attributes:
        dense_dir: workspace folder (``results/{scene}/final/dense``).
    """

    dense_dir: Path

    @property
    def fused_ply(self) -> Path:
        return Path(self.dense_dir) / "fused.ply"

    @property
    def summary_json(self) -> Path:
        return Path(self.dense_dir) / "dense_summary.json"


def choose_backend(cfg: DenseConfig) -> str:
    """``colmap_cuda`` when asked for (or auto) and pycolmap has CUDA, else ``taichi``.

    Raises:
        RuntimeError: ``backend: colmap_cuda`` but this pycolmap has no CUDA.
    """
    if cfg.backend == "colmap_cuda" and not pycolmap.has_cuda:
        raise RuntimeError(
            "dense.backend is colmap_cuda but the installed pycolmap has no CUDA "
            "(pycolmap.has_cuda is False): install a CUDA build of pycolmap or set "
            "dense.backend to auto/taichi"
        )
    if cfg.backend in ("auto", "colmap_cuda") and pycolmap.has_cuda:
        return "colmap_cuda"
    return "taichi"


def _subsample(plans: list[ViewPlan], max_views: int) -> list[ViewPlan]:
    if max_views <= 0 or len(plans) <= max_views:
        return plans
    idx = np.unique(np.round(np.linspace(0, len(plans) - 1, max_views)).astype(int))
    return [plans[i] for i in idx]


def _run_taichi(
    cfg: DenseConfig,
    rec: pycolmap.Reconstruction,
    plans: list[ViewPlan],
    dense_dir: Path,
    pool: ViewPool,
) -> list[dict]:
    """Photometric pass, geometric pass and filter for every planned view, each step's views
    spread over the pool's workers."""
    LOG.info("dense: taichi PatchMatch on %s, %d views, %d process(es)", taichi_arch(),
             len(plans), pool.workers)  # fmt: skip
    tasks = passes.view_tasks(rec, plans)
    shared = passes.PassSettings(cfg.patchmatch, dense_dir)
    stats = [{"name": p.name} for p in plans]
    for step in (passes.photometric, passes.geometric, passes.filtered):
        t0 = time.perf_counter()
        for st, out in zip(stats, pool.map(step, tasks, shared), strict=True):
            st.update(out)
        LOG.info("dense: %s step of %d views, %.1f s", step.__name__, len(plans),
                 time.perf_counter() - t0)  # fmt: skip
    passes.install_filtered(dense_dir, [p.name for p in plans])
    return stats


def _run_colmap_cuda(cfg: DenseConfig, plans: list[ViewPlan], dense_dir: Path) -> list[dict]:
    """pycolmap.patch_match_stereo (CUDA) with the same sources and depth ranges."""
    per_view = run_patch_match(cfg, dense_dir) / max(len(plans), 1)
    return [{"name": p.name, "colmap_cuda_s": per_view} for p in plans]


def fuse(cfg: DenseConfig, dense_dir: Path) -> pycolmap.Reconstruction:
    """pycolmap.stereo_fusion of the geometric maps into ``fused.ply``.

    Raises:
        RuntimeError: fusion produced no point (names the settings to relax).
    """
    opts = pycolmap.StereoFusionOptions()
    opts.num_threads = cfg.num_threads
    opts.min_num_pixels = cfg.fusion_min_num_pixels
    opts.max_reproj_error = cfg.fusion_max_reproj_error
    opts.max_depth_error = cfg.fusion_max_depth_error
    opts.max_normal_error = cfg.fusion_max_normal_error_deg
    opts.max_image_size = cfg.max_image_size
    fused = pycolmap.stereo_fusion(
        str(dense_dir / "fused.ply"),
        str(dense_dir),
        workspace_format="COLMAP",
        input_type="geometric",
        options=opts,
        output_type="PLY",
    )
    if fused.num_points3D() == 0:
        raise RuntimeError(
            f"dense: stereo fusion in {dense_dir} produced no point; check the depth maps in "
            "stereo/depth_maps or relax dense.fusion_min_num_pixels / fusion_max_*_error"
        )
    return fused


def poisson_mesh(ply: Path, out: Path, depth: int) -> None:
    """Screened Poisson mesh of the fused cloud (open3d), low-density vertices trimmed."""
    import open3d as o3d

    pcd = o3d.io.read_point_cloud(str(ply))
    if not pcd.has_normals():
        pcd.estimate_normals()
    mesh, dens = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(pcd, depth=depth)
    dens = np.asarray(dens)
    mesh.remove_vertices_by_mask(dens < np.quantile(dens, 0.05))
    o3d.io.write_triangle_mesh(str(out), mesh)


def run(cfg: DenseConfig, inputs: DenseInputs, outputs: DenseOutputs) -> dict:
    """Run dense MVS on the final map.

    Args:
        cfg: dense settings.
        inputs: sparse model and photo folder.
        outputs: dense workspace folder.

    Returns:
        The summary written to ``dense_summary.json``.

    Raises:
        FileNotFoundError: model files or registered photos missing (named in the message).
        ValueError: fewer than 2 registered views, or views without any overlapping view
            (named) when ``skip_isolated_views`` is false.
    """
    t_start = time.perf_counter()
    dense_dir = Path(outputs.dense_dir)
    ws.check_inputs(inputs.sparse_dir, inputs.image_dir)
    rec = ws.undistort(inputs.sparse_dir, inputs.image_dir, dense_dir, cfg.max_image_size)
    # a re-run estimates every depth map again: the measured maps a previous run kept beside
    # its plane-completed ones would otherwise be completed instead of the new ones
    for kind in ("depth", "normal"):
        shutil.rmtree(dense_dir / "stereo" / f"{kind}_maps_measured", ignore_errors=True)
    plans, isolated = _plan_views(cfg, rec)
    ws.write_configs(dense_dir, {p.name: [rec.image(s).name for s in p.sources] for p in plans})
    backend = choose_backend(cfg)
    with one_blas_thread(), _view_pool(cfg, backend, dense_dir) as pool:
        t0 = time.perf_counter()
        if backend == "colmap_cuda":
            view_stats = _run_colmap_cuda(cfg, plans, dense_dir)
        else:
            view_stats = _run_taichi(cfg, rec, plans, dense_dir, pool)
        t_depth = time.perf_counter() - t0
        fill_stats = None
        if cfg.plane_fill.enabled:
            fill_stats = _run_plane_fill(cfg, rec, plans, dense_dir, view_stats, pool)
    t0 = time.perf_counter()
    fused = fuse(cfg, dense_dir)
    t_fusion = time.perf_counter() - t0
    if cfg.poisson_mesh:
        poisson_mesh(outputs.fused_ply, dense_dir / "meshed-poisson.ply", cfg.poisson_depth)
    _add_plan_stats(view_stats, plans, rec)
    summary = {
        "backend": backend,
        "taichi_arch": None if backend != "taichi" else taichi_arch(),
        "processes": pool.workers,
        "num_views": len(plans),
        "skipped_views": isolated,
        "image_size": [rec.camera(rec.image(plans[0].image_id).camera_id).width,
                       rec.camera(rec.image(plans[0].image_id).camera_id).height],
        "num_fused_points": int(fused.num_points3D()),
        "depth_seconds": t_depth,
        "plane_fill": fill_stats,
        "fusion_seconds": t_fusion,
        "total_seconds": time.perf_counter() - t_start,  # the pictures after: plots_seconds
        "config": cfg.model_dump(),
        "views": view_stats,
    }  # fmt: skip
    if cfg.plots:
        t0 = time.perf_counter()
        with one_blas_thread():  # (N, 3) products of the cloud's millions of points
            _plots(rec, plans, dense_dir, outputs.fused_ply, fill_stats is not None)
        summary["plots_seconds"] = time.perf_counter() - t0
    outputs.summary_json.write_text(json.dumps(summary, indent=1))
    return summary


def _view_pool(cfg: DenseConfig, backend: str, dense_dir: Path) -> ViewPool:
    """The processes that run the views: ``num_threads`` workers (taichi on one thread each)
    where taichi runs on the CPU; this process alone on a GPU or with COLMAP's CUDA."""
    on_cpu = False
    if backend == "taichi":
        on_cpu = init_taichi(cfg.taichi_arch, cfg.num_threads, cfg.patchmatch.seed) in (
            "x64", "arm64")  # fmt: skip
    return ViewPool(worker_count(cfg.num_threads, on_cpu), cfg.patchmatch.seed,
                    dense_dir / "stereo")  # fmt: skip


def _plan_views(cfg: DenseConfig, rec: pycolmap.Reconstruction) -> tuple[list[ViewPlan], list]:
    """The reference views with their sources (at most ``max_views``) and the names of the
    views left out for want of an overlapping view.

    Raises:
        ValueError: views without any overlapping view (named) when ``skip_isolated_views``
            is false, or no view with one.
    """
    plans, isolated = select_views(
        rec,
        num_sources=cfg.num_source_views,
        min_shared_points=cfg.min_shared_points,
        min_angle_deg=cfg.min_triangulation_angle_deg,
        depth_margin=cfg.depth_margin,
        full_angle_deg=cfg.full_angle_deg,
    )
    if isolated and (not cfg.skip_isolated_views or not plans):
        raise ValueError(
            f"dense: {len(isolated)} view(s) share no usable overlap (>= {cfg.min_shared_points}"
            f" sparse points at >= {cfg.min_triangulation_angle_deg} deg) with any other view: "
            + ", ".join(isolated[:10])
            + (" ..." if len(isolated) > 10 else "")
            + "; set dense.skip_isolated_views: true (the default) to leave them out, or lower "
            "dense.min_shared_points / dense.min_triangulation_angle_deg"
        )
    for name in isolated:
        LOG.warning("dense: view %s has no overlapping view, skipped", name)
    return _subsample(plans, cfg.max_views), isolated


def _run_plane_fill(
    cfg: DenseConfig,
    rec: pycolmap.Reconstruction,
    plans: list[ViewPlan],
    dense_dir: Path,
    view_stats: list[dict],
    pool: ViewPool,
) -> dict:
    """Plane completion of the geometric maps (each view's fill on the pool's workers); each
    view's share of pixels filled and culled is added to its ``view_stats``. Returns the
    plane fill's stats without its views."""
    from scenebot.dense.planefill import plane_fill

    fill_views = []
    for p in plans:
        img = rec.image(p.image_id)
        pose = img.cam_from_world()
        fill_views.append((p.name, rec.camera(img.camera_id).calibration_matrix(),
                           pose.rotation.matrix(), np.asarray(pose.translation),
                           p.depth_range))  # fmt: skip
    fill_stats = plane_fill(dense_dir, fill_views, cfg.plane_fill, pool=pool)
    by_name = {v["name"]: v for v in fill_stats.pop("views")}
    for st in view_stats:
        v = by_name.get(st["name"], {})
        st["fraction_plane_filled"] = v.get("filled")
        st["fraction_culled_behind_plane"] = v.get("culled")
    LOG.info(
        "dense: %d planes; %.1f %% of the pixels filled from them, %.1f %% of measured "
        "depth behind a plane removed (%.0f s)",
        len(fill_stats["planes"]), 100 * fill_stats["filled_fraction"],
        100 * fill_stats["culled_fraction"], fill_stats["seconds"],
    )  # fmt: skip
    return fill_stats


def _add_plan_stats(
    view_stats: list[dict], plans: list[ViewPlan], rec: pycolmap.Reconstruction
) -> None:
    """Add each view's sources, shared points, angles and depth range to its stats."""
    for p, st in zip(plans, view_stats, strict=True):
        st.update(
            sources=[rec.image(s).name for s in p.sources],
            shared_points=p.shared_points,
            median_angle_deg=[round(a, 2) for a in p.median_angle_deg],
            depth_range=list(p.depth_range),
        )


def _plots(
    rec: pycolmap.Reconstruction,
    plans: list[ViewPlan],
    dense_dir: Path,
    fused_ply: Path,
    plane_filled: bool,
) -> None:
    """The fused cloud's views, the depth and normal mosaic and the planes from above (a
    note that the plane fill is off when it did not run)."""
    from scenebot.dense import plots
    from scenebot.dense.planes.store import PLANES_NPZ

    t0 = time.perf_counter()
    plots.plot_fused_views(fused_ply, rec, dense_dir / "fused_views.png")
    LOG.info("dense: fused_views.png in %.1f s", time.perf_counter() - t0)
    plots.plot_depth_mosaic(
        dense_dir, [p.name for p in plans], dense_dir / "depth_normal_mosaic.png"
    )
    planes_npz = dense_dir / PLANES_NPZ
    if not plane_filled:
        planes_npz.unlink(missing_ok=True)  # a previous run's planes are not this run's
    plots.plot_planes(planes_npz if plane_filled else None, dense_dir / "planes.png")
