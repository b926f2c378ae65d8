"""Tour path: smooth, through the capture positions, clear of the geometry; bad input."""

from __future__ import annotations

import numpy as np
import pytest

from scenebot.testing import dense as syn
from scenebot.tour.camera import TourInputError
from scenebot.tour.config import PathConfig
from scenebot.tour.path import ClearanceChecker, cluster_waypoints, plan_tour
from tests.fixtures.tour import rig


@pytest.fixture(scope="module")
def room_points():
    scene = syn.box_room_scene(seed=0)
    return syn.sample_surface(scene.vertices, scene.triangles, 100000, seed=0)


def test_waypoints_cluster_consecutive_photos():
    centers, _ = rig(per_stop=10)
    wp = cluster_waypoints(centers, 0.25)
    assert len(wp) == 3
    np.testing.assert_allclose(wp[:, :2], [(-0.8, -0.4), (-0.6, 0.5), (0.4, 0.0)], atol=1e-9)


def test_path_is_smooth_clear_and_passes_the_stops(room_points):
    centers, _ = rig(per_stop=10)
    cfg = PathConfig(frames=120)
    checker = ClearanceChecker(
        room_points, cfg.clearance_m, 0.0, cfg.height_band_m, min_points=cfg.obstacle_min_points
    )
    path = plan_tour(centers, cfg, checker)
    assert len(path) == 120 and path.dropped == 0
    assert path.kind == "spline"
    # every position keeps the clearance from the true surfaces at camera height
    band = room_points[np.abs(room_points[:, 2]) < 0.2]
    d = np.min(np.linalg.norm(path.positions[:, None, :2] - band[None, ::20, :2], axis=2), axis=1)
    assert d.min() > 0.2
    # passes within 2 cm of every stop, at constant speed, at camera height
    for w in path.waypoints:
        assert np.min(np.linalg.norm(path.positions - w, axis=1)) < 0.02
    step = np.linalg.norm(np.diff(path.positions, axis=0), axis=1)
    assert step.max() < 1.2 * np.median(step)
    assert np.allclose(path.positions[:, 2], 0.0)
    # smooth headings: small turn per frame
    assert np.max(np.abs(np.diff(path.headings))) < np.radians(8)
    R, t = path.pose(10)
    np.testing.assert_allclose(-R.T @ t, path.positions[10], atol=1e-12)


def test_single_stop_turns_in_place():
    centers = np.zeros((5, 3)) + np.array([0.01, 0.0, 0.0]) * np.arange(5)[:, None]
    path = plan_tour(centers, PathConfig(frames=36))
    assert path.kind == "orbit"
    assert np.ptp(path.positions, axis=0).max() < 1e-9
    assert np.isclose(np.ptp(path.headings), 2 * np.pi * 35 / 36)


def test_no_valid_pose_is_a_clear_error(room_points):
    centers, _ = rig(per_stop=4)
    # nothing is 5 m from a wall
    checker = ClearanceChecker(
        room_points, 5.0, 0.0, 0.3, min_points=PathConfig().obstacle_min_points
    )
    with pytest.raises(TourInputError, match=r"tour\.path\.clearance_m"):
        plan_tour(centers, PathConfig(frames=20), checker)
    with pytest.raises(TourInputError, match="no registered photo"):
        plan_tour(np.zeros((0, 3)), PathConfig(frames=20))


def test_path_through_an_obstacle_falls_back_or_drops(room_points):
    # a pillar right on the spline between two stops, off the straight segments
    centers = np.array([[0, 0, 0], [1, 1, 0], [2, 0, 0], [3, 1, 0.0]])
    pillar = np.random.default_rng(0).normal([1.5, 0.9, 0], [0.02, 0.02, 0.1], (200, 3))
    cfg = PathConfig(frames=80, clearance_m=0.1)
    checker = ClearanceChecker(pillar, 0.1, 0.0, 0.3, min_points=cfg.obstacle_min_points)
    path = plan_tour(centers, cfg, checker)
    d = np.min(np.linalg.norm(path.positions[:, None, :2] - pillar[None, :, :2], axis=2), axis=1)
    assert d.min() >= 0.1
