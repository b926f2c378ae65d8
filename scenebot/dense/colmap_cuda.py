"""COLMAP's PatchMatch stereo (``pycolmap.patch_match_stereo``, CUDA only) with scenebot's
dense settings, so the stage and the benchmarks run it the same way.

This module imports pycolmap and the dense config only (no taichi): a machine with the CUDA
pycolmap wheel can run it without the rest of the dense stage's dependencies.
"""

from __future__ import annotations

import time
from pathlib import Path

import pycolmap

from scenebot.dense.config import DenseConfig


def patch_match_options(
    cfg: DenseConfig, depth_range: tuple[float, float] | None = None
) -> pycolmap.PatchMatchOptions:
    """COLMAP PatchMatch options matching ``cfg`` (window, geometric pass, filter, threads).

    Args:
        cfg: dense settings.
        depth_range: (min, max) depth searched in every view; None: COLMAP takes each view's
            range from the sparse points, as the taichi backend does.
    """
    opts = pycolmap.PatchMatchOptions()
    opts.max_image_size = cfg.max_image_size
    opts.window_radius = max(cfg.patchmatch.window_radius, 3)
    opts.geom_consistency = cfg.patchmatch.geom_iterations > 0
    opts.filter = True
    opts.filter_min_num_consistent = max(cfg.patchmatch.filter_min_consistent, 1)
    opts.num_threads = cfg.num_threads
    if depth_range is not None:
        opts.depth_min, opts.depth_max = float(depth_range[0]), float(depth_range[1])
    return opts


def run_patch_match(
    cfg: DenseConfig, dense_dir: Path, depth_range: tuple[float, float] | None = None
) -> float:
    """Run COLMAP's PatchMatch over the workspace ``dense_dir``; returns the wall seconds.

    Raises:
        RuntimeError: this pycolmap has no CUDA (names the wheel to install).
    """
    if not pycolmap.has_cuda:
        raise RuntimeError(
            "pycolmap.patch_match_stereo needs the CUDA build of pycolmap (pip install "
            "pycolmap-cuda12 on a machine with an NVIDIA GPU); this one is CPU-only"
        )
    t0 = time.perf_counter()
    pycolmap.patch_match_stereo(str(dense_dir), options=patch_match_options(cfg, depth_range))
    return time.perf_counter() - t0
