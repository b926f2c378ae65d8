"""Sensors against known geometry: ultrasonic, compass, camera pose."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scenebot.config import Config
from scenebot.robot.base import ULTRASONIC_NO_ECHO_CM, Pose2D
from scenebot.sim.world import SimWorld

SEED = Config().seed


def test_ultrasonic_measures_the_distance_to_a_wall(room, no_noise_cfg):
    world = SimWorld(room, no_noise_cfg, Pose2D(3.0, 1.5, 0.0), seed=SEED)
    sensor_x = 3.0 + no_noise_cfg.body.radius_m - 0.02
    # the cone's central ray hits the wall x = 4 perpendicularly
    assert world.ultrasonic_cm() == pytest.approx((4.0 - sensor_x) * 100, abs=1.5)


def test_ultrasonic_reports_no_echo_beyond_its_range(no_noise_cfg):
    from tests.fixtures.rooms import box_room

    big = box_room(size=(8.0, 3.0), start=(1.0, 1.5, 0.0))
    world = SimWorld(big, no_noise_cfg, Pose2D(1.0, 1.5, 0.0), seed=SEED)
    assert world.ultrasonic_cm() == ULTRASONIC_NO_ECHO_CM  # wall 6.9 m away


def test_compass_follows_heading_with_noise(room, sim_cfg):
    sim_cfg.sensors.compass_noise_deg = 1.0
    world = SimWorld(room, sim_cfg, Pose2D(2.0, 1.5, math.radians(30)), seed=4)
    readings = np.array([world.compass_deg() for _ in range(400)])
    assert readings.mean() == pytest.approx(30.0, abs=0.2)
    assert readings.std() == pytest.approx(1.0, rel=0.15)


def test_camera_is_mounted_off_the_rotation_axis(room, sim_cfg):
    world = SimWorld(room, sim_cfg, Pose2D(2.0, 1.5, math.pi / 2), seed=SEED)
    R, c = world.camera_pose()
    cam = sim_cfg.camera
    assert c == pytest.approx([2.0, 1.5 + cam.forward_offset_m, cam.height_m])
    assert R[2] == pytest.approx([0.0, 1.0, 0.0], abs=1e-12)  # looks along the heading
    assert R[1] == pytest.approx([0.0, 0.0, -1.0], abs=1e-12)  # image y points down
    assert np.linalg.det(R) == pytest.approx(1.0)
