"""Taichi set-up shared by the tour kernels: one initialisation per process."""

from __future__ import annotations

import logging
import os

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")

import taichi as ti

LOG = logging.getLogger(__name__)


def init_taichi(arch: str = "auto", num_threads: int = -1) -> str:
    """Initialise taichi unless this process already did (another stage may have).

    Args:
        arch: ``auto`` (CUDA, then Vulkan, then CPU), ``gpu`` (CUDA or Vulkan, else CPU with a
            warning) or ``cpu``.
        num_threads: CPU threads (-1 = all cores).

    Returns:
        The arch taichi runs on (``x64``, ``arm64``, ``cuda``, ``vulkan``).
    """
    if ti.lang.impl.get_runtime().prog is None:
        kwargs: dict = {"default_fp": ti.f32, "offline_cache": True, "log_level": ti.WARN}
        if num_threads > 0:
            kwargs["cpu_max_num_threads"] = num_threads
        archs = [ti.cpu] if arch == "cpu" else [ti.cuda, ti.vulkan, ti.cpu]
        ti.init(arch=archs, **kwargs)
    name = str(ti.lang.impl.current_cfg().arch).split(".")[-1]
    if arch == "gpu" and name in ("x64", "arm64"):
        LOG.warning("tour taichi_arch=gpu requested but no CUDA/Vulkan device: running on CPU")
    return name
