"""The simulated person (``robot: person-sim``, scenebot/robot/person_sim.py): where it can
stand, its errors against its settings, the walk along the walls, reading the guide's map;
on a small synthetic room (a box with a table), no rendering but one photo."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scenebot.geometry import similarity_fit, view_direction
from scenebot.robot.person_config import PersonSimConfig
from scenebot.robot.person_sim import (
    ShotPose,
    SimPerson,
    map_to_world,
    perimeter_walk,
    resample_closed,
    shot_in_world,
)
from scenebot.scene.mesh import Material, SceneBuilder

ROOM = (4.0, 3.0, 2.5)
TABLE = ((2.5, 1.0), (3.3, 1.8))  # x0, y0 .. x1, y1 (m), 0.75 m high


def room():
    """A 4 x 3 x 2.5 m room with a table, walls facing in."""
    b = SceneBuilder("person-room")
    rng = np.random.default_rng(0)
    tex = rng.integers(0, 255, (32, 32, 3), dtype=np.uint8)
    wall = b.material(Material("wall", tex))
    w, d, h = ROOM
    b.box((0, 0, -0.1), (w, d, 0), wall)  # floor slab
    b.box((0, 0, h), (w, d, h + 0.1), wall)  # ceiling slab
    b.box((-0.1, -0.1, 0), (0, d + 0.1, h), wall)
    b.box((w, -0.1, 0), (w + 0.1, d + 0.1, h), wall)
    b.box((0, -0.1, 0), (w, 0, h), wall)
    b.box((0, d, 0), (w, d + 0.1, h), wall)
    (x0, y0), (x1, y1) = TABLE
    b.box((x0, y0, 0), (x1, y1, 0.75), wall)
    b.light((w / 2, d / 2, h - 0.2))
    return b.build()


class Camera:
    """sim.camera's settings the person's camera reads."""

    width, height, hfov_deg = 32, 24, 70.0
    noise_sigma, antialias, sensor_width_mm, jpeg_quality = 1.0, False, 6.17, 90


@pytest.fixture(scope="module")
def scene():
    return room()


def person(scene, seed=1, **kw) -> SimPerson:
    return SimPerson(scene, PersonSimConfig(**kw), Camera(), [seed, 1], seed)


def test_it_stands_in_the_room_but_not_in_the_table_or_outside(scene):
    p = person(scene)
    assert p.can_stand((1.0, 1.5))
    assert not p.can_stand((2.9, 1.4))  # in the table
    assert not p.can_stand((2.9, 0.9))  # beside it, within clearance_m (0.25)
    assert p.can_stand((2.9, 0.6))
    assert not p.can_stand((5.0, 1.5))  # outside the walls
    assert not p.can_stand((0.1, 1.5))  # against the wall
    assert not p.can_stand((-3.0, 40.0))  # off the map


def test_a_shot_it_cannot_reach_is_skipped_and_named(scene):
    p = person(scene)  # reach_m 0.5: the table's middle is 0.65 m from where it fits
    shot = p.shoot(ShotPose(np.array([2.9, 1.4, 1.5]), 0.0, 0.0))
    assert shot.taken is None and "(2.90, 1.40)" in shot.skipped
    assert "reach_m = 0.5" in shot.skipped
    shot = p.shoot(ShotPose(np.array([6.0, 1.5, 1.5]), 0.0, 0.0))
    assert shot.taken is None and "outside the room" in shot.skipped


def test_it_holds_the_camera_out_over_the_table_but_not_into_it(scene):
    p = person(scene, reach_m=0.8, position_std_m=0.0, height_std_m=0.0)
    over = p.shoot(ShotPose(np.array([2.9, 1.4, 1.5]), 0.0, 0.0))
    assert np.allclose(over.taken.center, [2.9, 1.4, 1.5])
    stood = np.array(over.extra["stood_at"])
    assert p.can_stand(stood) and 0.6 < np.linalg.norm(stood - [2.9, 1.4]) <= 0.8
    into = p.shoot(ShotPose(np.array([2.9, 1.4, 0.5]), 0.0, 0.0))  # below the table top
    assert into.taken is None and "inside or behind furniture" in into.skipped


def test_the_errors_follow_the_settings(scene):
    cfg = {"position_std_m": 0.2, "heading_std_deg": 10.0, "pitch_std_deg": 5.0,
           "height_std_m": 0.05}  # fmt: skip
    p = person(scene, seed=4, **cfg)
    aimed = ShotPose(np.array([1.2, 1.5, 1.5]), 0.5, math.radians(20.0))
    shots = [p.shoot(aimed).taken for _ in range(600)]
    dxy = np.array([s.center[:2] - aimed.center[:2] for s in shots])
    dh = np.degrees([math.remainder(s.heading - aimed.heading, 2 * math.pi) for s in shots])
    dp = np.degrees([s.pitch - aimed.pitch for s in shots])
    assert np.all(np.abs(dxy.mean(0)) < 0.03)
    assert np.all(np.abs(dxy.std(0) - 0.2) < 0.03)
    assert abs(dh.mean()) < 1.5 and abs(dh.std() - 10.0) < 1.0
    assert abs(dp.mean()) < 0.8 and abs(dp.std() - 5.0) < 0.6
    assert all(p.can_stand(s.center[:2]) for s in shots)  # never in the furniture


def test_its_height_is_its_own(scene):
    heights = {person(scene, seed=s).eye_height_m for s in range(40)}
    assert len(heights) == 40 and min(heights) >= 1.2 and max(heights) <= 1.8
    assert max(heights) - min(heights) > 0.4  # drawn across the range
    p = person(scene, seed=3, height_std_m=0.0)
    lo, hi = p.camera_height_range()
    assert lo == pytest.approx(0.4) and hi == pytest.approx(p.eye_height_m + 0.3)
    up = p.shoot(ShotPose(np.array([1.2, 1.5, 2.4]), 0.0, 0.0)).taken
    down = p.shoot(ShotPose(np.array([1.2, 1.5, 0.1]), 0.0, 0.0)).taken
    assert up.center[2] == pytest.approx(hi) and down.center[2] == pytest.approx(lo)
    assert person(scene, seed=3).eye_height_m == p.eye_height_m  # same seed, same person


def test_the_perimeter_walk_is_evenly_spaced_along_the_walls_facing_in(scene):
    p = person(scene, seed=2)
    n, inset = 24, 0.6
    walk = perimeter_walk(p, n, inset)
    assert len(walk) == n
    xy = np.array([s.center[:2] for s in walk])
    moved = 0
    for s in walk:
        assert p.can_stand(s.center[:2])
        assert s.center[2] == pytest.approx(p.eye_height_m)
        assert s.pitch == 0.0
        # facing into the room: away from the nearest wall (square to the walk: in a
        # corner the nearest wall may be the one beside)
        away = s.center[:2] - p.walls.nearest_obstacle(s.center[:2])
        assert view_direction(s.heading)[:2] @ away / np.linalg.norm(away) > 0.2
        # on the line inset_m from the walls, or stepped aside from the table standing on it
        if abs(p.walls.clearance_at(s.center[:2]) - inset) > 0.03:
            moved += 1
            (x0, y0), (x1, y1) = TABLE
            assert x0 - 0.6 < s.center[0] < x1 + 0.6 and y0 - 0.6 < s.center[1] < y1 + 0.6
    assert 0 < moved < n / 3
    # even spacing by arc length: consecutive photos about length / n apart
    step = np.linalg.norm(np.diff(np.vstack([xy, xy[:1]]), axis=0), axis=1)
    length = 2 * (ROOM[0] - 2 * inset + ROOM[1] - 2 * inset)  # the rectangle inside
    assert np.median(step) == pytest.approx(length / n, rel=0.1)
    # it goes all the way around: the walk's photos face every wall
    headings = np.degrees([s.heading for s in walk]) % 360
    assert len({int(((h + 45) % 360) // 90) for h in headings}) == 4


def two_rooms():
    """Two 3.9 x 3 m rooms side by side, a doorway (1 m wide, 2 m high, a lintel above) in
    the wall between them."""
    b = SceneBuilder("person-two-rooms")
    tex = np.random.default_rng(0).integers(0, 255, (32, 32, 3), dtype=np.uint8)
    wall = b.material(Material("wall", tex))
    w, d, h = 8.0, 3.0, 2.5
    b.box((0, 0, -0.1), (w, d, 0), wall)
    b.box((0, 0, h), (w, d, h + 0.1), wall)
    b.box((-0.1, -0.1, 0), (0, d + 0.1, h), wall)
    b.box((w, -0.1, 0), (w + 0.1, d + 0.1, h), wall)
    b.box((0, -0.1, 0), (w, 0, h), wall)
    b.box((0, d, 0), (w, d + 0.1, h), wall)
    b.box((3.9, 0, 0), (4.1, 1.0, h), wall)  # the wall between, the doorway at y 1..2
    b.box((3.9, 2.0, 0), (4.1, d, h), wall)
    b.box((3.9, 1.0, 2.0), (4.1, 2.0, h), wall)  # lintel
    b.light((2.0, 1.5, h - 0.2))
    b.light((6.0, 1.5, h - 0.2))
    return b.build()


def test_the_walk_goes_through_every_room(scene):
    """Two rooms joined by a doorway: the walk goes along the walls of both, and through
    the doorway between them photographing ahead; a single room's walk stays as it was."""
    flat = two_rooms()
    p = SimPerson(flat, PersonSimConfig(), Camera(), [3, 1], 3)
    n = 40
    walk = perimeter_walk(p, n, 0.6)
    assert len(walk) == n
    xy = np.array([s.center[:2] for s in walk])
    assert all(p.can_stand(c) for c in xy)
    left, right = xy[:, 0] < 3.9, xy[:, 0] > 4.1
    assert left.sum() >= n / 3 and right.sum() >= n / 3
    # through the doorway: photos near it face along the passage (+-x), not a wall
    door = (np.abs(xy[:, 0] - 4.0) < 0.6) & (np.abs(xy[:, 1] - 1.5) < 0.5)
    assert door.any()
    assert all(abs(math.cos(walk[i].heading)) > 0.7 for i in np.flatnonzero(door))
    # photos evenly spaced over the whole walk (a room's loop, the passage, the other's)
    step = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    assert np.median(step) == pytest.approx(np.median(step[: n // 4]), rel=0.15)
    assert step.max() < 4 * np.median(step)


def test_resampling_a_closed_line_spaces_points_evenly():
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    pts = resample_closed(square, 8)
    step = np.linalg.norm(np.diff(np.vstack([pts, pts[:1]]), axis=0), axis=1)
    assert np.allclose(step, 0.5)


def test_it_reads_the_guides_map_through_its_own_photos():
    rng = np.random.default_rng(5)
    world = rng.uniform(0, 4, (12, 3))
    ang = 0.7
    R = np.array([[math.cos(ang), -math.sin(ang), 0], [math.sin(ang), math.cos(ang), 0],
                  [0, 0, 1]])  # fmt: skip
    s, t = 0.5, np.array([1.0, -2.0, 0.3])
    in_map = (world - t) @ R / s  # world = s R map + t
    sim = map_to_world(in_map, world)
    assert sim[0] == pytest.approx(s) and np.allclose(sim[1], R) and np.allclose(sim[2], t)
    goal = {"x": 0.2, "y": 0.4, "z": -0.1, "theta": 0.3, "pitch": -0.2}
    w = shot_in_world(goal, sim)
    assert np.allclose(w.center, s * R @ [0.2, 0.4, -0.1] + t)
    assert w.heading == pytest.approx(0.3 + ang) and w.pitch == pytest.approx(-0.2)
    with pytest.raises(ValueError, match="needs 3"):
        map_to_world(in_map[:2], world[:2])
    # photos registered metres off do not mislead it
    off = in_map.copy()
    off[:4] += rng.uniform(2, 5, (4, 3)) / s
    s3, R3, t3 = map_to_world(off, world)
    assert s3 == pytest.approx(s) and np.allclose(R3, R) and np.allclose(t3, t)
    s2, R2, t2 = similarity_fit(in_map, world)
    assert np.allclose(s2 * in_map @ R2.T + t2, world)


def test_a_photo_is_rendered_with_its_truth(scene, tmp_path):
    p = person(scene)
    pose = ShotPose(np.array([1.0, 1.5, 1.4]), 0.0, math.radians(10), math.radians(3))
    truth = p.take(pose, tmp_path / "a.jpg")
    from PIL import Image

    with Image.open(tmp_path / "a.jpg") as im:
        assert im.size == (32, 24)
    R = np.array(truth["R_cam_from_world"])
    assert np.allclose(truth["center"], pose.center)
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-9)
    assert np.allclose(R[2], view_direction(0.0, math.radians(10)))  # roll keeps the axis
    with pytest.raises(Exception, match="exists"):
        p.take(pose, tmp_path / "a.jpg")  # never over a photo


def _tracked(rec: dict) -> tuple[np.ndarray, np.ndarray]:
    m = rec["motion"]
    return np.array(m["center"]), np.array(m["R_cam_from_session"])


def test_the_phones_motion_is_the_walk_in_its_own_frame_with_its_drift(scene):
    """The tracked poses are the true ones in a level frame of the session's own heading and
    origin: relative poses match the truth, up to a drift near motion_drift of the distance
    walked; none without tracking (motion_drift null); the orientation records unchanged."""
    from scenebot.robot.person_sim import orientation_record, phone_motion

    rng = np.random.default_rng(5)
    walk = [ShotPose(np.array([0.5 + 0.1 * k, 1.0 + 0.02 * k, 1.5]), rng.uniform(-3, 3), 0.0)
            for k in range(30)]  # fmt: skip
    exact = phone_motion(person(scene, motion_drift=0.0), "round_000")
    recs = [exact.record(p) for p in walk]
    c0, R0 = _tracked(recs[0])
    assert np.allclose(c0, 0.0) and recs[0]["motion"]["walked_m"] == 0.0
    for p, rec in zip(walk, recs, strict=True):
        c, R = _tracked(rec)
        assert np.allclose(R @ R.T, np.eye(3), atol=1e-6)
        assert R[2, :] @ [0, 0, 1] == pytest.approx(p.rotation()[2] @ [0, 0, 1], abs=1e-6)
        # the relative pose of the first photo and this one is the true one
        assert np.allclose(R @ R0.T, p.rotation() @ walk[0].rotation().T, atol=1e-5)
        assert np.allclose(R @ (c0 - c), p.rotation() @ (walk[0].center - p.center), atol=1e-4)
    assert recs[-1]["motion"]["walked_m"] == pytest.approx(29 * math.hypot(0.1, 0.02), rel=1e-3)
    errors = []
    for seed in range(20):
        drifting = phone_motion(person(scene, seed=seed, motion_drift=0.02), "round_000")
        c = [_tracked(drifting.record(p))[0] for p in walk]
        true = np.linalg.norm(walk[-1].center - walk[0].center)
        errors.append(abs(np.linalg.norm(c[-1] - c[0]) - true))
    assert 0.0 < np.median(errors) < 3 * 0.02 * 29 * 0.102  # of the 2.96 m walked
    assert phone_motion(person(scene, motion_drift=None), "round_000") is None
    with_tracking, without = person(scene, seed=3), person(scene, seed=3, motion_drift=None)
    phone_motion(with_tracking, "round_000").record(walk[1])
    assert orientation_record(with_tracking, walk[0]) == orientation_record(without, walk[0])
