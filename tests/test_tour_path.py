"""Tour path: smooth, through the capture positions, clear of the geometry; bad input."""

from __future__ import annotations

import itertools

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


# --------------------------------------------------------------------------- tour order
def _turns_deg(path) -> np.ndarray:
    return np.degrees(np.abs(np.diff(np.stack([path.headings, path.pitches]), axis=1)).max(0))


def test_short_tour_matches_brute_force():
    from scenebot.tour.path import _tour_length, short_tour

    rng = np.random.default_rng(3)
    for _ in range(12):
        p = rng.uniform(0, 1, (7, 2))
        cost = np.linalg.norm(p[:, None] - p[None], axis=2)
        tour = short_tour(cost, start=2)
        assert tour[0] == 2 and sorted(tour) == list(range(7))
        best = min(
            _tour_length(np.array((0, *q)), cost) for q in itertools.permutations(range(1, 7))
        )
        assert _tour_length(tour, cost) <= 1.03 * best


def _cross(u, v):
    return u[0] * v[1] - u[1] * v[0]


def _point_segment(p, a, b):
    ab = b - a
    t = np.clip(((p - a) @ ab) / max(ab @ ab, 1e-12), 0, 1)
    return np.linalg.norm(p - (a + t * ab))


def test_robot_tour_is_a_smooth_loop_not_zigzag_legs(room_points):
    # six stops visited criss-cross (each leg crosses the room), as adaptive rounds do
    stops = ((-1.2, -0.9), (0.9, 0.8), (-1.2, 0.8), (0.9, -0.9), (-0.2, 0.9), (-0.2, -0.9))
    centers, _ = rig(stops, per_stop=12)
    cfg = PathConfig(frames=200)
    checker = ClearanceChecker(
        room_points, cfg.clearance_m, 0.0, cfg.height_band_m, min_points=cfg.obstacle_min_points
    )
    path = plan_tour(centers, cfg, checker)
    st = np.array(stops)
    capture_len = np.linalg.norm(np.diff(st, axis=0), axis=1).sum()
    wp = path.waypoints[:, :2]
    loop = np.concatenate([wp, wp[:1]]) if path.closed else wp
    tour_len = np.linalg.norm(np.diff(loop, axis=0), axis=1).sum()
    assert path.closed and len(wp) == 6
    # a walk around, not back and forth: the shortest loop (brute force), far shorter than
    # the capture order
    best = min(
        np.linalg.norm(np.diff(st[[0, *q, 0]], axis=0), axis=1).sum()
        for q in itertools.permutations(range(1, 6))
    )
    assert tour_len < 1.01 * best + 0.1  # stops moved clear of the cloud by a few cm at most
    assert tour_len < 0.75 * capture_len
    # legs of the loop never cross each other
    segs = list(itertools.pairwise(loop))
    for i, (a, b) in enumerate(segs):
        for c, d in segs[i + 2 : len(segs) - (i == 0)]:
            o = [_cross(b - a, q - a) for q in (c, d)] + [_cross(d - c, q - c) for q in (a, b)]
            assert not (o[0] * o[1] < 0 and o[2] * o[3] < 0)
    assert len(path) == 200 and path.dropped == 0
    assert checker.ok(path.positions[:, :2]).all()
    # within the photos' region: near the loop through the stops
    leg = np.median(np.linalg.norm(np.diff(loop, axis=0), axis=1))
    for p in path.positions[:, :2]:
        assert min(_point_segment(p, a, b) for a, b in segs) < 0.35 * leg
    # smooth: constant speed, bounded turn per frame, level camera at camera height
    step = np.linalg.norm(np.diff(path.positions, axis=0), axis=1)
    assert step.max() < 1.3 * np.median(step)
    turns = _turns_deg(path)  # at most max_turn_deg, or twice the mean where it must turn more
    assert turns.max() <= max(cfg.max_turn_deg, 2.2 * turns.mean()) and turns.max() < 6
    assert np.allclose(path.pitches, 0) and np.allclose(path.positions[:, 2], 0)


def test_robot_looks_where_a_fan_of_photos_looked():
    # stop A: a circle of photos (they look every way); stop B: a fan towards +y (a goal)
    circle, _ = rig(((0.0, 0.0),), per_stop=12)
    fan_h = np.radians(90 + np.array([-30, -15, 0, 15, 30]))
    fan = np.array([[2.0, 0.0, 0.0]] * 5)
    third, _ = rig(((1.0, -1.2),), per_stop=12)
    centers = np.concatenate([circle, fan, third])
    heads = np.concatenate(
        [np.linspace(0, 2 * np.pi, 12, endpoint=False), fan_h,
         np.linspace(0, 2 * np.pi, 12, endpoint=False)]
    )  # fmt: skip
    fwd = np.stack([np.cos(heads), np.sin(heads), 0 * heads], -1)
    targets = centers + 1.5 * fwd  # each photo sees a wall 1.5 m ahead
    cfg = PathConfig(frames=150)
    path = plan_tour(centers, cfg, targets=targets)
    near_fan = np.linalg.norm(path.positions[:, :2] - [2.0, 0.0], axis=1) < 0.1
    assert near_fan.any()
    h = np.degrees(np.angle(np.exp(1j * path.headings[near_fan])))
    assert np.all(np.abs(h - 90) < 20)  # looks where the fan looked
    # at the circles the view follows the path (swaying), it does not stare at one point
    near_circle = np.linalg.norm(path.positions[:, :2], axis=1) < 0.15
    assert np.isnan(path.targets[near_circle]).all()


# --------------------------------------------------------------------------- a person's photos
def ring_capture(scale: float = 1.0, gap: int = 3, n: int = 16):
    """Photos on a ring of radius 4 around an object at the origin, 0.5 above it, looking
    at it; ``gap`` consecutive photos missing. Units arbitrary (SfM units x ``scale``).

    Returns:
        centers (N, 3), targets (N, 3) (where each photo's axis meets the object's surface),
        the object's cloud (K, 3).
    """
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)[gap:]
    rng = np.random.default_rng(0)
    a = a + rng.normal(0, 0.03, len(a))
    centers = np.stack([4 * np.cos(a), 4 * np.sin(a), 0.5 + 0 * a], -1)
    fwd = -centers / np.linalg.norm(centers, axis=1, keepdims=True)
    d = np.linalg.norm(centers, axis=1) - 0.8  # the object: a ball of radius 0.8
    targets = centers + d[:, None] * fwd
    ball = rng.normal(size=(4000, 3))
    ball = 0.8 * ball / np.linalg.norm(ball, axis=1, keepdims=True)
    return scale * centers, scale * targets, scale * ball


def _photos_path(scale: float, frames: int = 120):
    from scenebot.tour.config import TourConfig
    from scenebot.tour.stage import scaled_lengths

    centers, targets, ball = ring_capture(scale)
    # the stage's units for a person's photos: the photos see the object at about 3.3 units
    cfg = scaled_lengths(TourConfig(path={"frames": frames}), 3.3 * scale / 2.0)
    checker = ClearanceChecker(
        ball, cfg.path.clearance_m, None, 0.0, min_points=cfg.path.obstacle_min_points
    )
    path = plan_tour(centers, cfg.path, checker, targets=targets, photos=True)
    return path, centers, cfg


def test_photos_path_keeps_the_subject_in_view():
    path, _, cfg = _photos_path(1.0)
    assert len(path) == 120 and path.dropped == 0
    # a ring with a gap: an open arc through the photos, never across the gap
    assert not path.closed and len(path.waypoints) == 13
    ang = np.degrees(np.arctan2(path.positions[:, 1], path.positions[:, 0])) % 360
    assert not ((ang > 5) & (ang < 62)).any()  # the missing photos at 0, 22.5, 45 degrees
    # within the photos' region: on the ring, at the photos' height
    r = np.linalg.norm(path.positions[:, :2], axis=1)
    assert np.all(np.abs(r - 4) < 0.2) and np.allclose(path.positions[:, 2], 0.5, atol=0.05)
    # looks at the subject: the view axis passes through the object (radius 0.8, at 4), near
    # its centre, pitched down to it
    fwd = path.forward()
    to_obj = -path.positions / np.linalg.norm(path.positions, axis=1, keepdims=True)
    err = np.degrees(np.arccos(np.clip((fwd * to_obj).sum(1), -1, 1)))
    assert err.max() < 0.5 * np.degrees(np.arcsin(0.8 / 4))
    assert np.all(path.pitches < 0)
    # smooth: constant speed, bounded turn per frame
    step = np.linalg.norm(np.diff(path.positions, axis=0), axis=1)
    assert step.max() < 1.3 * np.median(step)
    turns = _turns_deg(path)
    assert turns.max() <= max(cfg.path.max_turn_deg, 2.2 * turns.mean()) and turns.max() < 6


def test_photos_path_is_the_same_in_any_unit():
    # no metric scale: the same photos in units 1000x larger give the same tour, 1000x larger
    a, _, _ = _photos_path(1.0, frames=60)
    b, _, _ = _photos_path(1000.0, frames=60)
    np.testing.assert_allclose(b.positions, 1000 * a.positions, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(b.headings, a.headings, atol=1e-9)
    np.testing.assert_allclose(b.pitches, a.pitches, atol=1e-9)


def test_photos_path_bends_around_the_object():
    # two photos on opposite sides of the object: the straight leg would go through it
    centers, targets, ball = ring_capture(1.0, gap=0, n=16)
    pick = [0, 1, 8, 9]
    cfg = PathConfig(frames=80, cluster_radius_m=0.1, clearance_m=0.6)
    checker = ClearanceChecker(ball, 0.6, None, 0.0, min_points=cfg.obstacle_min_points)
    path = plan_tour(centers[pick], cfg, checker, targets=targets[pick], photos=True)
    d = np.linalg.norm(path.positions[:, None] - ball[None, ::10], axis=2).min(1)
    assert d.min() >= 0.6 - 1e-6
    assert len(path) >= 72  # bent around rather than dropped
