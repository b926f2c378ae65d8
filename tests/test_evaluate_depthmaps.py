"""Per-view depth-map evaluation against the true scene (issue 7's per-view figures)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from scenebot.dense import workspace as ws
from scenebot.dense.colmap_io import write_array
from scenebot.evaluate.config import EvaluateConfig
from scenebot.evaluate.depthmaps import evaluate_depth_maps
from scenebot.evaluate.metrics import Similarity
from scenebot.testing.dense import box_room_scene, make_dataset, stereo_rig

W, H = 96, 72
EVAL = EvaluateConfig()


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    root = tmp_path_factory.mktemp("dm")
    sc = box_room_scene()
    centers, headings = stereo_rig(num_per_row=2, half_width_m=0.3)
    _, views = make_dataset(root, sc, centers, headings, W, H, num_points=800)
    dense = root / "dense"
    ws.undistort(root / "sparse", root / "images", dense, max_image_size=W)
    # materials: the room's triangles "wall", the boxes' "box"
    mids = np.zeros(len(sc.triangles), np.int64)
    mids[12:] = 1
    scene = SimpleNamespace(
        vertices=sc.vertices, triangles=sc.triangles, material_ids=mids,
        materials=[SimpleNamespace(name="wall"), SimpleNamespace(name="box")],
    )  # fmt: skip
    return dense, views, scene


def _write(dense, views, kind, fn):
    folder = dense / "stereo" / ("depth_maps" if kind == "final" else "depth_maps_measured")
    folder.mkdir(parents=True, exist_ok=True)
    for v in views:
        d = np.where(np.isfinite(v.depth), v.depth, 0).astype(np.float32)
        write_array(folder / f"{v.name}.geometric.bin", fn(d))


def test_exact_maps_are_complete_and_right_and_biased_ones_are_not(workspace):
    dense, views, scene = workspace
    identity = Similarity(1.0, np.eye(3), np.zeros(3), len(views), {})
    _write(dense, views, "final", lambda d: d)
    half = np.ones((H, W), bool)
    half[:, : W // 2] = False
    _write(dense, views, "measured", lambda d: np.where(half, d * 1.05, 0))  # 5% too far
    out = evaluate_depth_maps(dense, identity, scene, EVAL.depth_rel_tol, EVAL.depth_map_views)
    fin, mea = out["summary"]["final"], out["summary"]["measured"]
    assert fin["views"] == len(views)
    assert fin["coverage_median"] > 0.99 and fin["within_2pct_median"] > 0.99
    assert fin["views_meeting_bars"] == len(views)
    assert 0.4 < mea["coverage_median"] < 0.6 and mea["within_2pct_median"] < 0.01
    assert mea["views_meeting_bars"] == 0
    by = {r["material"]: r for r in out["by_material"]["final"]}
    assert set(by) == {"wall", "box"} and by["wall"]["with_depth"] > 0.99
    assert sum(r["pixel_share"] for r in by.values()) == pytest.approx(1.0)


def test_a_wrong_map_frame_counts_against_the_maps(workspace):
    """The truth is ray-cast through the map's similarity: a map 3% too large in scale puts
    every depth 3% off, however good the maps are in their own frame."""
    dense, views, scene = workspace
    _write(dense, views, "final", lambda d: d)
    off = Similarity(1.03, np.eye(3), np.zeros(3), len(views), {})
    out = evaluate_depth_maps(dense, off, scene, EVAL.depth_rel_tol, EVAL.depth_map_views)
    fin = out["summary"]["final"]
    assert fin["within_2pct_median"] < 0.05


def test_no_depth_maps_is_an_error_naming_the_folder(tmp_path):
    with pytest.raises(FileNotFoundError, match="sparse"):
        evaluate_depth_maps(tmp_path, None, None, EVAL.depth_rel_tol, EVAL.depth_map_views)
