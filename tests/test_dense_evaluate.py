"""Metrics of the dense stage against known geometry."""

import numpy as np
import pytest

from scenebot.dense.evaluate import (
    cloud_metrics,
    depth_map_metrics,
    normal_angle_deg,
    sample_surface,
    visible_surface_samples,
)
from scenebot.testing.dense import box_room_scene, intrinsics, look_at_pose


def test_depth_map_metrics():
    true = np.full((10, 10), 2.0, np.float32)
    true[0] = 0.0  # no surface: ignored
    pred = true * 1.01
    pred[1, :5] = 0.0  # 5 of 90 pixels without depth
    pred[2, :9] = 2.2  # 9 wrong by 10 %
    m = depth_map_metrics(pred, true)
    assert m["coverage"] == pytest.approx(85 / 90)
    assert m["accuracy"] == pytest.approx(76 / 85)
    assert m["median_rel_error"] == pytest.approx(0.01, rel=1e-3)


def test_normal_angle():
    a = np.zeros((2, 2, 3))
    a[..., 2] = -1
    b = a.copy()
    b[0, 0] = [0, -1, 0]
    assert sorted(normal_angle_deg(a, b).round(3).tolist()) == [0, 0, 0, 90]


def test_cloud_metrics_perfect_and_offset():
    sc = box_room_scene()
    ref = sample_surface(sc.vertices, sc.triangles, 20000, seed=1)
    pts = sample_surface(sc.vertices, sc.triangles, 200000, seed=2)
    m = cloud_metrics(pts, sc.vertices, sc.triangles, ref)
    assert m["1cm"]["accuracy"] == pytest.approx(1.0)
    # 200k points on ~70 m^2: ~2 cm spacing, so complete at 5 cm, nearly so at 2 cm
    assert m["2cm"]["completeness"] > 0.95
    assert m["5cm"]["completeness"] > 0.999
    assert m["5cm"]["fscore"] > 0.999
    # every point moved 3 cm off a planar room part: inaccurate at 1-2 cm, accurate at 5 cm
    room_only = sc.vertices[:8]
    tri = sc.triangles[:12]
    on_floor = sample_surface(room_only, tri, 50000, seed=3)
    on_floor = on_floor[np.abs(on_floor[:, 2] - room_only[:, 2].min()) < 1e-9]
    moved = on_floor + np.array([0, 0, 0.03])
    moved = moved[(np.abs(moved[:, 0]) < 1.5) & (np.abs(moved[:, 1]) < 1.0)]
    m = cloud_metrics(moved, room_only, tri, on_floor)
    assert m["2cm"]["accuracy"] == 0.0
    assert m["5cm"]["accuracy"] == 1.0
    with pytest.raises(ValueError, match="empty"):
        cloud_metrics(np.zeros((0, 3)), room_only, tri, on_floor)


def test_visible_samples_are_in_front_of_a_camera():
    sc = box_room_scene()
    K = intrinsics(160, 120)
    cams = [(K, *look_at_pose(np.array([0.0, y, 0.0]), 0.0), 160, 120) for y in (-0.1, 0.1)]
    pts = visible_surface_samples(sc.vertices, sc.triangles, cams, spacing_m=0.02)
    assert len(pts) > 1000
    assert np.all(pts[:, 0] > 0.5)  # cameras look along +x: nothing behind them is visible
