"""The same taichi PatchMatch kernels on a GPU (CUDA or Vulkan), when one is present."""

import json
import subprocess
import sys

import pytest

SCRIPT = r"""
import json, time
import cv2, numpy as np
from scenebot.dense.config import PatchMatchConfig
from scenebot.dense.evaluate import depth_map_metrics
from scenebot.dense.patchmatch import PatchMatchSolver, StereoView
from scenebot.taichi_setup import init_taichi
from scenebot.testing.dense import box_room_scene, intrinsics, look_at_pose, render_view
arch = init_taichi("gpu", -1)
sc = box_room_scene()
K = intrinsics(320, 240)
views, truth = [], []
for k, y in enumerate(np.linspace(-0.3, 0.3, 5)):
    R, t = look_at_pose(np.array([0.0, y, 0.0]), 0.0)
    img, depth, _ = render_view(sc, K, R, t, 320, 240)
    gray = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY) / np.float32(255)
    views.append(StereoView(str(k), gray, K, R, t))
    truth.append(depth)
srcs = [views[i] for i in (0, 1, 3, 4)]
res = PatchMatchSolver(PatchMatchConfig()).estimate(views[2], srcs, (0.5, 4.5))
print(json.dumps({"arch": arch, **depth_map_metrics(res.depth, truth[2])}))
"""


@pytest.mark.gpu
def test_patchmatch_on_gpu():
    out = subprocess.run(
        [sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=600, check=True
    )
    res = json.loads(out.stdout.strip().splitlines()[-1])
    assert res["arch"] in ("cuda", "vulkan"), f"no GPU arch, taichi ran on {res['arch']}"
    assert res["accuracy"] > 0.85
    assert res["median_rel_error"] < 0.005
