"""Taichi, started once per process for the stages that run kernels on the CPU or a GPU
(dense PatchMatch and plane completion, the tour's renderer, the score-validity study).

The score stage starts taichi through :func:`scenebot.score.kernel.init_taichi`, which can
also switch backends within a process (its tests compare the CPU and GPU kernels).
"""

from __future__ import annotations

import logging
import os

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")  # nothing reaches the network

import taichi as ti

LOG = logging.getLogger(__name__)


def taichi_arch() -> str | None:
    """The arch taichi runs on (``x64``, ``arm64``, ``cuda``, ``vulkan``), or None before it
    was started."""
    if ti.lang.impl.get_runtime().prog is None:
        return None
    return str(ti.lang.impl.current_cfg().arch).split(".")[-1]


def init_taichi(arch: str, num_threads: int, seed: int = 0) -> str:
    """Start taichi unless this process already did (another stage may have: then its
    runtime is used as it is).

    Args:
        arch: ``auto`` (CUDA, then Vulkan, then CPU), ``gpu`` (CUDA or Vulkan, else CPU with a
            warning) or ``cpu``. ``ti.init(arch=ti.gpu)`` can crash a machine without a GPU,
            so the GPU backends are named one by one.
        num_threads: CPU threads (-1 = all cores).
        seed: seed of taichi's random generator, fixed for the whole process (the stages that
            draw random numbers in kernels pass their own setting, e.g. dense.patchmatch.seed).

    Returns:
        The arch taichi runs on.
    """
    if taichi_arch() is None:
        kwargs: dict = {
            "default_fp": ti.f32,
            "offline_cache": True,
            "log_level": ti.WARN,
            "random_seed": seed,
        }
        if num_threads > 0:
            kwargs["cpu_max_num_threads"] = num_threads
        archs = [ti.cpu] if arch == "cpu" else [ti.cuda, ti.vulkan, ti.cpu]
        ti.init(arch=archs, **kwargs)
    name = taichi_arch()
    if arch == "gpu" and name in ("x64", "arm64"):
        LOG.warning("taichi_arch=gpu requested but no CUDA/Vulkan device: running on CPU")
    return name
