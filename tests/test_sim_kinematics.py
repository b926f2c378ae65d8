"""Kinematics of the simulated robot: slip, odometry, collisions, bumpers, stall."""

from __future__ import annotations

import math

import pytest

from scenebot.robot.base import MotionStatus, Pose2D
from scenebot.robot.sim import SimRobot
from scenebot.sim.world import SimWorld, StartPoseError
from tests.fixtures.rooms import box_room


def make(scene, cfg, start, seed=0):
    world = SimWorld(scene, cfg, Pose2D(*start), seed=seed)
    return SimRobot(world), world


def test_drive_without_slip_is_exact(room, no_noise_cfg):
    robot, world = make(room, no_noise_cfg, (1.0, 1.5, 0.0))
    res = robot.drive(1.0)
    assert res.status is MotionStatus.COMPLETED
    assert world.truth_pose.x == pytest.approx(2.0, abs=0.005)
    assert world.truth_pose.y == pytest.approx(1.5, abs=1e-6)
    assert res.distance_m == pytest.approx(1.0, abs=0.005)
    assert robot.odometry.x == pytest.approx(1.0, abs=0.005)


def test_turn_slip_makes_the_robot_turn_less_than_odometry_says(room, sim_cfg):
    sim_cfg.slip.turn, sim_cfg.slip.turn_noise = 0.10, 0.0
    robot, world = make(room, sim_cfg, (2.0, 1.5, 0.0))
    theta0 = world.truth_pose.theta
    res = robot.turn(math.radians(90))
    true_turn = math.degrees(world.truth_pose.theta - theta0)
    assert math.degrees(res.angle_rad) == pytest.approx(90.0, abs=0.5)  # encoders
    assert true_turn == pytest.approx(81.0, abs=1.0)  # 10 % slip on the floor


def test_drive_slip_is_small_and_mostly_on_turns(room, sim_cfg):
    sim_cfg.slip.drive, sim_cfg.slip.drive_noise = 0.02, 0.0
    sim_cfg.slip.heading_drift_deg_per_m = 0.0
    robot, world = make(room, sim_cfg, (1.0, 1.5, 0.0))
    robot.drive(1.0)
    assert world.truth_pose.x - 1.0 == pytest.approx(0.98, abs=0.01)


@pytest.mark.parametrize("direction", [1, -1])
def test_wall_stops_the_robot_and_the_bumper_fires(room, no_noise_cfg, direction):
    # facing +x (forward) or -x (backing up) towards the wall at x = 4
    theta = 0.0 if direction > 0 else math.pi
    robot, world = make(room, no_noise_cfg, (3.0, 1.5, theta))
    res = robot.drive(direction * 2.0)
    assert res.status is MotionStatus.BUMPED
    assert res.bumper == ("front" if direction > 0 else "rear")
    radius = no_noise_cfg.body.radius_m
    x = world.truth_pose.x
    assert 4.0 - radius - 0.01 <= x <= 4.0 - radius + 0.002  # at the wall, not through it
    assert abs(res.distance_m) == pytest.approx(4.0 - radius - 3.0, abs=0.02)
    assert world.max_penetration_m < 0.003


def test_obstacle_above_the_bumpers_stalls_the_wheels(no_noise_cfg):
    # a shelf board between the bumpers' top (0.12 m) and the robot's top (0.40 m)
    scene = box_room(obstacles=[((2.5, 1.0, 0.2), (2.8, 2.0, 0.3))])
    robot, world = make(scene, no_noise_cfg, (1.5, 1.5, 0.0))
    res = robot.drive(2.0)
    assert res.status is MotionStatus.STALLED
    assert res.bumper is None
    assert world.truth_pose.x <= 2.5 - no_noise_cfg.body.radius_m + 0.002
    # backing away still works
    assert robot.drive(-0.3).status is MotionStatus.COMPLETED


def test_start_inside_an_obstacle_is_refused(no_noise_cfg):
    scene = box_room(obstacles=[((1.0, 1.0, 0.0), (1.5, 1.5, 0.5))])
    with pytest.raises(StartPoseError, match=r"world\.start"):
        make(scene, no_noise_cfg, (1.2, 1.2, 0.0))
