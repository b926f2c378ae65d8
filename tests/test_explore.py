"""Random exploration behaviour (paper IV.A) against the simulated robot."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from scenebot.capture.explore import PhotoTaker, best_heading, random_exploration
from scenebot.capturelog import CaptureLog, read_log
from scenebot.config import ExplorationConfig
from scenebot.robot.base import Camera, Pose2D
from scenebot.robot.sim import SimRobot
from scenebot.scene.office import office
from scenebot.sim.world import SimWorld
from tests.fixtures.rooms import box_room


class PoseOnlyCamera(Camera):
    """Records that a photo was taken (an empty file) without rendering: logic tests only."""

    def capture(self, dest: Path, timeout_s: float | None = None) -> Path:
        dest.parent.mkdir(parents=True, exist_ok=True)
        dest.write_bytes(b"")
        return dest


def explore(tmp_path, scene, cfg, start, photos, seed=0, **kw):
    world = SimWorld(scene, cfg, Pose2D(*start), seed=seed)
    robot = SimRobot(world)
    with CaptureLog(tmp_path / "log.jsonl") as log:
        taker = PhotoTaker(robot, PoseOnlyCamera(), log, tmp_path, "r000")
        ecfg = ExplorationConfig(photos=photos, **kw)
        result = random_exploration(robot, taker, log, ecfg, np.random.default_rng(seed))
    return result, world, list(read_log(tmp_path / "log.jsonl"))


def test_a_circle_is_36_photos_10_degrees_apart(tmp_path, room, no_noise_cfg):
    result, _, records = explore(tmp_path, room, no_noise_cfg, (2.0, 1.5, 0.0), 36)
    photos = [r for r in records if r["type"] == "photo"]
    assert len(photos) == 36 and result.circles == 1
    odo = np.unwrap([p["odometry"]["theta"] for p in photos])
    assert np.degrees(np.diff(odo)) == pytest.approx(np.full(35, 10.0), abs=0.2)
    true = np.unwrap([p["truth"]["robot"]["theta"] for p in photos])
    assert np.degrees(true[-1] - true[0]) == pytest.approx(350.0, abs=0.5)


def test_after_a_circle_the_robot_heads_for_the_longest_range(tmp_path, no_noise_cfg):
    # a long corridor along +x: the longest range is there (no echo)
    scene = box_room(size=(8.0, 1.6), start=(1.0, 0.8, 0.0))
    _, _, records = explore(tmp_path, scene, no_noise_cfg, (1.0, 0.8, math.pi / 2), 37)
    turn = next(r for r in records if r["type"] == "event" and r["event"] == "turn")
    assert turn["target_compass_deg"] == pytest.approx(0.0, abs=15) or turn[
        "target_compass_deg"
    ] == pytest.approx(360.0, abs=15)


def test_best_heading_prefers_no_echo_and_the_middle_of_a_run():
    readings = [(0.0, 80), (10.0, 255), (20.0, 255), (30.0, 255), (40.0, 120)]
    assert best_heading(readings) == 20.0


def test_a_bump_triggers_back_up_and_turn(tmp_path, no_noise_cfg):
    # facing a wall 0.5 m ahead after the circle: the drive must bump
    scene = box_room(size=(1.2, 3.0), start=(0.6, 1.5, 0.0))
    _, _world, records = explore(
        tmp_path, scene, no_noise_cfg, (0.6, 1.5, 0.0), 40, drive_min_m=1.5, drive_max_m=1.5
    )
    events = [r["event"] for r in records if r["type"] == "event"]
    assert "bump" in events or "stall" in events
    i = events.index("bump") if "bump" in events else events.index("stall")
    assert events[i + 1] == "backup" and events[i + 2] == "escape_turn"
    backup = next(r for r in records if r.get("event") == "backup")
    assert backup["distance_m"] == pytest.approx(-0.12, abs=0.01)


def test_the_robot_never_ends_inside_an_obstacle(tmp_path, sim_cfg):
    scene = office(7)
    _, world, records = explore(
        tmp_path, scene, sim_cfg, (scene.start.x, scene.start.y, scene.start.theta), 300, seed=3
    )
    radius = sim_cfg.body.radius_m
    assert world.max_penetration_m < 0.005
    poses = [r["truth"]["robot"] if "robot" in r["truth"] else r["truth"]
             for r in records if "truth" in r]  # fmt: skip
    clearance = [world.collision_map.clearance_at((p["x"], p["y"])) for p in poses]
    assert min(clearance) >= radius - 0.005
    events = [r["event"] for r in records if r["type"] == "event"]
    assert events.count("circle_done") >= 8  # it moved around
