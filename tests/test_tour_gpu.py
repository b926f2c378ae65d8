"""The ULR kernels on a GPU (taichi CUDA/Vulkan) give the CPU's image.

Each arch runs in its own process (taichi has one arch per process). Skipped when taichi finds
no GPU.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

SCRIPT = r"""
import json, os, sys
os.environ["TI_SKIP_VERSION_CHECK"] = "ON"
import numpy as np, pycolmap
from pathlib import Path
from scenebot.taichi_setup import init_taichi
from scenebot.tour.config import TourConfig
from scenebot.tour.proxy import load_proxy
from scenebot.tour.ulr import UlrRenderer, load_sources
root, arch, out = Path(sys.argv[1]), sys.argv[2], sys.argv[3]
name = init_taichi(arch, -1)
if arch == "gpu" and name in ("x64", "arm64"):
    print(json.dumps({"arch": name})); sys.exit(0)
cfg = TourConfig()
r = UlrRenderer(load_proxy(root / "fused.ply", cfg.proxy),
                load_sources(pycolmap.Reconstruction(str(root / "sfm")), root), cfg)
s = r.sources[4]
res = r.render(s.camera, s.R, s.t, exclude={4})
np.save(out, res.image)
print(json.dumps({"arch": name, "coverage": res.coverage}))
"""


def _render(root, arch, out):
    env = dict(os.environ, TI_SKIP_VERSION_CHECK="ON")
    p = subprocess.run(
        [sys.executable, "-c", SCRIPT, str(root), arch, str(out)],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert p.returncode == 0, p.stderr[-3000:]
    return json.loads(p.stdout.strip().splitlines()[-1])


@pytest.mark.gpu
def test_gpu_matches_cpu(tmp_path):
    from scenebot.tour.evaluate import psnr
    from tests.fixtures.tour import make_tour_dataset

    ds = make_tour_dataset(tmp_path / "capture", width=128, height=96, per_stop=10)
    gpu = _render(ds.root, "gpu", tmp_path / "gpu.npy")
    if gpu["arch"] in ("x64", "arm64"):
        pytest.skip("taichi found no CUDA/Vulkan device")
    cpu = _render(ds.root, "cpu", tmp_path / "cpu.npy")
    a, b = np.load(tmp_path / "gpu.npy"), np.load(tmp_path / "cpu.npy")
    assert gpu["coverage"] > 0.95 and abs(gpu["coverage"] - cpu["coverage"]) < 0.01
    assert psnr(a, b) > 40.0  # same algorithm; float order and atomics may differ slightly
