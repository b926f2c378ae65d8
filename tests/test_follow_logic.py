"""Path following against a small kinematic robot with slip (no renderer needed)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from scenebot.capture.follow import (
    FollowConfig,
    PathFollower,
    compose_odometry,
    robot_pose_from_camera,
)
from scenebot.capturelog import CaptureLog, read_log
from scenebot.localize.locate import FailureReason, LocalizationFailure, PoseEstimate
from scenebot.plan import PlanConfig, build_navgrid
from scenebot.plan.path import GridPlanner
from scenebot.robot.base import (
    Camera,
    Health,
    MotionResult,
    MotionStatus,
    Pose2D,
    Robot,
    SensorReading,
)
from tests.fixtures.localize import camera_rotation

SIMPLIFY = PlanConfig().simplify_factor

CAM_FWD = 0.1


class KinematicRobot(Robot):
    """A disk robot: turns slip by ``turn_slip`` and drives fall short by ``drive_short``
    (odometry sees neither); boxes bump it."""

    def __init__(self, pose, turn_slip=0.08, boxes=(), radius=0.15, odo_theta0=1.0,
                 drive_short=0.0):  # fmt: skip
        self.true = np.array(pose, float)
        self.turn_slip = turn_slip
        self.drive_short = drive_short
        self.boxes = [np.array(b, float) for b in boxes]  # (x0, y0, x1, y1)
        self.radius = radius
        self.t = 0.0
        # odometry frame: unrelated origin and heading offset
        self.odo = Pose2D(0.0, 0.0, odo_theta0)
        self.min_clearance = math.inf

    def _clearance(self, xy):
        c = math.inf
        for x0, y0, x1, y1 in self.boxes:
            dx = max(x0 - xy[0], 0.0, xy[0] - x1)
            dy = max(y0 - xy[1], 0.0, xy[1] - y1)
            c = min(c, math.hypot(dx, dy))
        return c

    def drive(self, distance_m):
        step = 0.005 * math.copysign(1.0, distance_m)
        done = 0.0
        status, bumper = MotionStatus.COMPLETED, None
        while abs(done) < abs(distance_m) - 1e-12:
            s = step if abs(distance_m - done) > abs(step) else distance_m - done
            ds = s * (1.0 - self.drive_short)
            nxt = self.true[:2] + ds * np.array([math.cos(self.true[2]), math.sin(self.true[2])])
            if self._clearance(nxt) < self.radius:
                status, bumper = MotionStatus.BUMPED, "front" if distance_m > 0 else "rear"
                break
            self.true[:2] = nxt
            done += s
        self.min_clearance = min(self.min_clearance, self._clearance(self.true[:2]))
        o = self.odo
        self.odo = Pose2D(o.x + done * math.cos(o.theta), o.y + done * math.sin(o.theta), o.theta)
        self.t += abs(done) / 0.2 + 0.1
        return MotionResult(status, done, 0.0, bumper, 0.1)

    def turn(self, angle_rad):
        self.true[2] += angle_rad * (1.0 - self.turn_slip)
        self.odo = Pose2D(self.odo.x, self.odo.y, (self.odo.theta + angle_rad) % (2 * math.pi))
        self.t += 0.5
        return MotionResult(MotionStatus.COMPLETED, 0.0, angle_rad, None, 0.5)

    def stop(self):
        pass

    def sense(self):
        # the compass reads the true heading (the map's x axis is compass heading 0)
        return SensorReading(self.t, math.degrees(self.true[2]) % 360, 255, False, False, self.odo)

    def health(self):
        return Health(8000, True)

    @property
    def now(self):
        return self.t

    def camera_pose(self):
        x, y, th = self.true
        c = np.array([x + CAM_FWD * math.cos(th), y + CAM_FWD * math.sin(th), 0.0])
        return camera_rotation(th), c


class NullCamera(Camera):
    def __init__(self):
        self.shots = 0

    def capture(self, dest: Path, timeout_s: float | None = None) -> Path:
        self.shots += 1
        return Path(dest)


class OracleLocalizer:
    """Test double for visual localization: the true camera pose plus noise, or failures."""

    def __init__(self, robot, sigma_m=0.005, sigma_deg=0.3, fail=lambda k: False, seed=0):
        self.robot = robot
        self.rng = np.random.default_rng(seed)
        self.sigma_m, self.sigma_deg, self.fail = sigma_m, sigma_deg, fail
        self.calls = 0

    def __call__(self, path):
        k = self.calls
        self.calls += 1
        if self.fail(k):
            return LocalizationFailure(FailureReason.TOO_FEW_MATCHES, 500, 3, 0)
        _, c = self.robot.camera_pose()
        th = self.robot.true[2] + math.radians(self.rng.normal(0, self.sigma_deg))
        R = camera_rotation(th)
        c = c + np.r_[self.rng.normal(0, self.sigma_m, 2), 0.0]
        return PoseEstimate(R, -R @ c, 520.0, 800, 300, 250, 0.8, "oracle")


def _open_grid():
    pts = np.zeros((0, 3))
    return build_navgrid(pts, np.array([[-1.0, -1.0], [5.0, 5.0]]), PlanConfig(margin_m=0.5))


def test_pose_math_roundtrips():
    fix = Pose2D(2.0, 1.0, 0.3)
    odo0 = Pose2D(5.0, -2.0, 2.0)
    # drive 1 m forward and turn 0.5 rad in odometry: the map pose moves the same way
    odo1 = Pose2D(5.0 + math.cos(2.0), -2.0 + math.sin(2.0), 2.5)
    p = compose_odometry(fix, odo0, odo1)
    assert (p.x, p.y) == pytest.approx((2.0 + math.cos(0.3), 1.0 + math.sin(0.3)))
    assert p.theta == pytest.approx(0.8)
    R = camera_rotation(1.0)
    c = np.array([1.0 + 0.1 * math.cos(1.0), 2.0 + 0.1 * math.sin(1.0), 0.0])
    est = PoseEstimate(R, -R @ c, 500.0, 1, 1, 1, 0.0, "x")
    q = robot_pose_from_camera(est, 0.1, 0.0)
    assert (q.x, q.y, q.theta) == pytest.approx((1.0, 2.0, 1.0))


def test_follows_a_path_with_turn_slip_and_reaches_the_goal(tmp_path):
    robot = KinematicRobot((0.0, 0.0, 0.0), turn_slip=0.1)
    loc = OracleLocalizer(robot)
    cfg = FollowConfig(camera_forward_m=CAM_FWD)
    with CaptureLog(tmp_path / "log.jsonl") as log:
        f = PathFollower(
            robot, NullCamera(), loc, GridPlanner(_open_grid(), SIMPLIFY), cfg, tmp_path, log
        )
        path = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.5, 3.0]])
        res = f.follow(path, goal_theta=math.pi / 2)
    assert res.reached and res.reason == "reached" and res.localized_at_goal
    assert math.hypot(robot.true[0] - 0.5, robot.true[1] - 3.0) < 0.1
    assert abs(math.remainder(robot.true[2] - math.pi / 2, 2 * math.pi)) < math.radians(5)
    events = [r["event"] for r in read_log(tmp_path / "log.jsonl")]
    assert events[0] == "follow_start" and events[-1] == "follow_end"
    assert events.count("target_node") >= 2  # switched B -> C -> D
    assert res.localizations >= 4


@pytest.mark.parametrize("compass_std_deg", [0.0, 2.0])
def test_without_localization_odometry_drifts_but_the_compass_keeps_the_heading(
    tmp_path, compass_std_deg
):
    robot = KinematicRobot((0.0, 0.0, 0.0), turn_slip=0.1)
    loc = OracleLocalizer(robot, fail=lambda k: True)  # every photo fails
    with CaptureLog(tmp_path / "log.jsonl") as log:
        f = PathFollower(
            robot,
            NullCamera(),
            loc,
            GridPlanner(_open_grid(), SIMPLIFY),
            FollowConfig(camera_forward_m=CAM_FWD, compass_std_deg=compass_std_deg),
            tmp_path,
            log,
            initial_pose=Pose2D(0.0, 0.0, 0.0),
        )
        res = f.follow(np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]]))
    assert res.reached and not res.localized_at_goal
    assert res.failed_localizations > 3 and res.localizations == 0
    miss = math.hypot(robot.true[0] - 2.0, robot.true[1] - 2.0)
    end = [r for r in read_log(tmp_path / "log.jsonl") if r["event"] == "follow_end"][-1]
    if compass_std_deg == 0:
        # the slipped 90 deg turn (9 deg short) left the robot off the goal: odometry alone
        assert miss > 0.1 and end["compass_updates"] == 0
    else:
        # the compass read after the turn corrects the heading before the robot drives on
        assert miss < 0.05 and end["compass_updates"] >= 2 and end["compass_rejected"] == 0


def test_a_disturbed_compass_reading_is_ignored(tmp_path):
    """A reading far beyond the heading's uncertainty (a magnet, a steel desk) is not fused."""

    class Disturbed(KinematicRobot):
        def sense(self):
            r = super().sense()
            if 1.0 < self.true[0] < 1.6:  # a disturbance over part of the first leg
                return SensorReading(
                    r.t, (r.compass_deg + 40.0) % 360, 255, False, False, r.odometry
                )
            return r

    robot = Disturbed((0.0, 0.0, 0.0), turn_slip=0.0)
    f = PathFollower(
        robot,
        NullCamera(),
        OracleLocalizer(robot, fail=lambda k: True),
        GridPlanner(_open_grid(), SIMPLIFY),
        FollowConfig(camera_forward_m=CAM_FWD, localize_every_m=0.2),
        tmp_path,
        initial_pose=Pose2D(0.0, 0.0, 0.0),
    )
    res = f.follow(np.array([[0.0, 0.0], [2.0, 0.0]]))
    assert res.reached and f.compass_rejected >= 1
    assert math.hypot(robot.true[0] - 2.0, robot.true[1]) < 0.05


def test_intermittent_localization_failures_are_retried_after_moving(tmp_path):
    robot = KinematicRobot((0.0, 0.0, 0.0), turn_slip=0.1)
    loc = OracleLocalizer(robot, fail=lambda k: k % 2 == 1)
    f = PathFollower(
        robot,
        NullCamera(),
        loc,
        GridPlanner(_open_grid(), SIMPLIFY),
        FollowConfig(camera_forward_m=CAM_FWD),
        tmp_path,
    )
    res = f.follow(np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.5, 3.0]]))
    assert res.reached and res.failed_localizations >= 1 and res.localizations >= 2
    assert math.hypot(robot.true[0] - 0.5, robot.true[1] - 3.0) < 0.1


def test_obstacle_missing_from_map_is_bumped_marked_and_avoided(tmp_path):
    robot = KinematicRobot((0.0, 0.0, 0.0), boxes=[(1.2, -0.4, 1.5, 0.4)])
    loc = OracleLocalizer(robot)
    planner = GridPlanner(_open_grid(), SIMPLIFY)
    f = PathFollower(
        robot, NullCamera(), loc, planner, FollowConfig(camera_forward_m=CAM_FWD), tmp_path
    )
    res = f.go_to(np.array([3.0, 0.0]))
    assert res.reached, res.reason
    assert 1 <= res.obstacles < 5 and res.replans == res.obstacles
    assert math.hypot(robot.true[0] - 3.0, robot.true[1]) < 0.1
    assert robot.min_clearance >= robot.radius - 1e-9  # never drove through the box


def test_unreachable_goal_is_abandoned_after_k_obstacles_with_reason(tmp_path):
    # the goal sits inside a closed pen the map does not know about
    pen = [
        (2.4, -0.6, 3.6, -0.5),
        (2.4, 0.5, 3.6, 0.6),
        (2.4, -0.6, 2.5, 0.6),
        (3.5, -0.6, 3.6, 0.6),
    ]
    robot = KinematicRobot((0.0, 0.0, 0.0), boxes=pen)
    loc = OracleLocalizer(robot)
    with CaptureLog(tmp_path / "log.jsonl") as log:
        f = PathFollower(
            robot,
            NullCamera(),
            loc,
            GridPlanner(_open_grid(), SIMPLIFY),
            FollowConfig(camera_forward_m=CAM_FWD, max_obstacles=5),
            tmp_path,
            log,
        )
        res = f.go_to(np.array([3.0, 0.0]))
    assert not res.reached
    assert res.obstacles == 5 or "replanning failed" in res.reason
    assert "obstacle" in res.reason
    end = [r for r in read_log(tmp_path / "log.jsonl") if r.get("event") == "follow_end"][-1]
    assert end["reached"] is False and end["reason"] == res.reason
    json.dumps(end)  # the log record is plain JSON
    assert robot.min_clearance >= robot.radius - 1e-9


def test_goal_in_obstacle_or_outside_grid_is_skipped_with_reason(tmp_path):
    robot = KinematicRobot((0.0, 0.0, 0.0))
    f = PathFollower(
        robot,
        NullCamera(),
        OracleLocalizer(robot),
        GridPlanner(_open_grid(), SIMPLIFY),
        FollowConfig(camera_forward_m=CAM_FWD),
        tmp_path,
    )
    res = f.go_to(np.array([50.0, 0.0]))
    assert not res.reached and res.reason.startswith("skipped") and "outside" in res.reason
    assert res.motions == 0


def test_go_to_view_puts_the_camera_centre_on_the_goal(tmp_path):
    robot = KinematicRobot((0.0, 0.0, 0.0), turn_slip=0.05)
    f = PathFollower(
        robot,
        NullCamera(),
        OracleLocalizer(robot),
        GridPlanner(_open_grid(), SIMPLIFY),
        FollowConfig(camera_forward_m=CAM_FWD),
        tmp_path,
    )
    res = f.go_to_view(np.array([2.0, 1.0]), heading=math.pi)
    assert res.reached
    _, c = robot.camera_pose()
    assert math.hypot(c[0] - 2.0, c[1] - 1.0) < 0.1
    assert abs(math.remainder(robot.true[2] - math.pi, 2 * math.pi)) < math.radians(3)


class AliasingLocalizer(OracleLocalizer):
    """Returns a confident pose shifted by ``shift`` (a repeated texture) on chosen calls."""

    def __init__(self, robot, wrong, shift=(2.0, 0.0)):
        super().__init__(robot)
        self.wrong, self.shift = wrong, np.array([*shift, 0.0])

    def __call__(self, path):
        k = self.calls
        est = super().__call__(path)
        if self.wrong(k):
            c = est.center + self.shift
            return PoseEstimate(est.R, -est.R @ c, 520.0, 800, 300, 250, 0.8, "oracle")
        return est


def test_a_confident_wrong_fix_is_rejected_by_the_odometry_gate(tmp_path):
    robot = KinematicRobot((0.0, 0.0, 0.0), turn_slip=0.05)
    loc = AliasingLocalizer(robot, wrong=lambda k: k == 2)
    with CaptureLog(tmp_path / "log.jsonl") as log:
        f = PathFollower(
            robot,
            NullCamera(),
            loc,
            GridPlanner(_open_grid(), SIMPLIFY),
            FollowConfig(camera_forward_m=CAM_FWD),
            tmp_path,
            log,
        )
        res = f.follow(np.array([[0.0, 0.0], [1.5, 0.0], [1.5, 1.5]]))
    assert res.reached and math.hypot(robot.true[0] - 1.5, robot.true[1] - 1.5) < 0.1
    rejected = [r for r in read_log(tmp_path / "log.jsonl") if r["event"] == "localize_rejected"]
    assert len(rejected) == 1 and rejected[0]["reason"] == "inconsistent_with_odometry"


def test_two_agreeing_fixes_override_a_wrong_initial_pose(tmp_path):
    robot = KinematicRobot((0.0, 0.0, 0.0))
    f = PathFollower(
        robot,
        NullCamera(),
        OracleLocalizer(robot),
        GridPlanner(_open_grid(), SIMPLIFY),
        FollowConfig(camera_forward_m=CAM_FWD),
        tmp_path,
        initial_pose=Pose2D(1.5, 1.0, 0.0),  # 1.8 m off: the first fix is rejected
    )
    res = f.follow(np.array([[1.5, 1.0], [2.0, 0.5]]))
    assert res.reached and math.hypot(robot.true[0] - 2.0, robot.true[1] - 0.5) < 0.1
    assert res.failed_localizations >= 1


@pytest.mark.parametrize(("turn_deg", "taken"), [(5.0, False), (40.0, True)])
def test_agreeing_fixes_override_the_prediction_only_from_different_views(
    tmp_path, turn_deg, taken
):
    """The robot knows where it is (initial pose = truth); a repeated texture then gives two
    confident fixes 2.4 m off that agree with each other. Taken a few degrees apart (one view
    of one wall) they do not override the odometry prediction; after a turn of
    follow.override_min_turn_deg or more they do (the prediction could be the wrong one)."""
    robot = KinematicRobot((0.5, 0.5, 0.0), turn_slip=0.0)
    loc = AliasingLocalizer(robot, wrong=lambda k: True, shift=(2.4, 0.0))
    f = PathFollower(
        robot,
        NullCamera(),
        loc,
        GridPlanner(_open_grid(), SIMPLIFY),
        FollowConfig(camera_forward_m=CAM_FWD, compass_gate_deg=0.0),
        tmp_path,
        initial_pose=Pose2D(0.5, 0.5, 0.0),
    )
    first = f.localize_photo(tmp_path / "a.jpg", robot.sense().odometry)
    assert isinstance(first, LocalizationFailure)
    assert first.reason == FailureReason.INCONSISTENT_WITH_ODOMETRY
    robot.turn(math.radians(turn_deg))
    second = f.localize_photo(tmp_path / "b.jpg", robot.sense().odometry)
    assert isinstance(second, PoseEstimate) is taken
    assert (math.hypot(f.pose.x - 0.5, f.pose.y - 0.5) > 2.0) is taken


class MirrorLocalizer(OracleLocalizer):
    """From call ``start`` on, confident fixes turned by 180 degrees and moved (the same
    texture seen from the other side of the room): consecutive ones agree with each other."""

    def __init__(self, robot, start=2, shift=(1.0, 0.8)):
        super().__init__(robot)
        self.start, self.shift = start, np.array([*shift, 0.0])

    def __call__(self, path):
        k = self.calls
        est = super().__call__(path)
        if k < self.start:
            return est
        th = math.atan2(est.R[2, 1], est.R[2, 0]) + math.pi
        R = camera_rotation(th)
        c = est.center + self.shift
        return PoseEstimate(R, -R @ c, 520.0, 800, 300, 250, 0.8, "oracle")


@pytest.mark.parametrize("gate_deg", [45.0, 0.0])
def test_mirrored_fixes_are_rejected_by_the_compass_even_when_they_agree(tmp_path, gate_deg):
    robot = KinematicRobot((0.0, 0.0, 0.0), turn_slip=0.05)
    with CaptureLog(tmp_path / "log.jsonl") as log:
        f = PathFollower(
            robot,
            NullCamera(),
            MirrorLocalizer(robot),
            GridPlanner(_open_grid(), SIMPLIFY),
            FollowConfig(camera_forward_m=CAM_FWD, compass_gate_deg=gate_deg),
            tmp_path,
            log,
        )
        res = f.follow(np.array([[0.0, 0.0], [1.5, 0.0], [1.5, 1.5]]))
    events = list(read_log(tmp_path / "log.jsonl"))
    by_compass = [r for r in events if r.get("reason") == "inconsistent_with_compass"]
    accepted = [r for r in events if r["event"] == "localize"]
    if gate_deg > 0:
        assert by_compass and all(r["heading_off_deg"] > 135 for r in by_compass)
        assert len(accepted) == 2  # only the two true fixes before the mirror began
        assert res.reached and math.hypot(robot.true[0] - 1.5, robot.true[1] - 1.5) < 0.15
    else:  # without the compass the agreeing mirrored fixes take over
        assert not by_compass and len(accepted) > 2


class GlitchAtGoalLocalizer(OracleLocalizer):
    """The first fix within ``radius`` of ``goal`` says the robot stands exactly there (one
    confident wrong pose, as in a poorly textured corner); every other fix is right."""

    def __init__(self, robot, goal, radius=0.15):
        super().__init__(robot, sigma_m=0.003, sigma_deg=0.2)
        self.goal, self.radius, self.glitched = np.asarray(goal, float), radius, False

    def __call__(self, path):
        est = super().__call__(path)
        x, y, th = self.robot.true
        if not self.glitched and math.hypot(x - self.goal[0], y - self.goal[1]) < self.radius:
            self.glitched = True
            c = np.r_[self.goal + CAM_FWD * np.array([math.cos(th), math.sin(th)]), 0.0]
            return PoseEstimate(est.R, -est.R @ c, 520.0, 800, 300, 250, 0.8, "oracle")
        return est


@pytest.mark.parametrize("confirm_m", [0.0, 0.06])
def test_a_goal_is_reached_only_on_a_fix_a_second_view_confirms(tmp_path, confirm_m):
    """Drives fall 25 % short, so the robot arrives 12 cm before the goal, where one wrong fix
    says it is there. A second view (after a turn in place) must agree before the goal counts
    as reached (``confirm_m``); without the check that one fix ends the approach."""
    goal = (1.5, 0.0)
    robot = KinematicRobot((0.0, 0.0, 0.0), turn_slip=0.0, drive_short=0.25)
    loc = GlitchAtGoalLocalizer(robot, goal)
    cfg = FollowConfig(camera_forward_m=CAM_FWD, confirm_m=confirm_m)
    f = PathFollower(robot, NullCamera(), loc, GridPlanner(_open_grid(), SIMPLIFY), cfg, tmp_path)
    res = f.follow(np.array([[0.0, 0.0], goal]))
    true_off = math.hypot(robot.true[0] - goal[0], robot.true[1] - goal[1])
    assert loc.glitched and res.reached and res.localized_at_goal
    assert res.goal_xy == pytest.approx(goal)
    if confirm_m > 0:
        assert res.confirmed_at_goal and true_off < 0.06
    else:
        assert true_off > 0.08  # the wrong fix ended it


@pytest.mark.parametrize("clear_m", [0.0, 1.0])
def test_after_giving_up_the_robot_leaves_a_blind_pocket_by_the_way_it_came(tmp_path, clear_m):
    # a pocket open to the west the map does not know about; the goal lies beyond its end
    # wall, and no photo localizes (a close wall): the robot bumps its way around inside
    pocket = [(0.8, 0.45, 2.2, 0.55), (0.8, -0.55, 2.2, -0.45), (2.1, -0.55, 2.2, 0.55)]
    robot = KinematicRobot((0.0, 0.0, 0.0), boxes=pocket, turn_slip=0.0)
    loc = OracleLocalizer(robot, fail=lambda k: k > 0)  # the start is known, then nothing
    with CaptureLog(tmp_path / "log.jsonl") as log:
        f = PathFollower(robot, NullCamera(), loc, GridPlanner(_open_grid(), SIMPLIFY),
                         FollowConfig(camera_forward_m=CAM_FWD, max_obstacles=3,
                                      retrace_clear_m=clear_m), tmp_path, log,
                         truth=lambda: {"truth_xy": robot.true[:2].tolist()})  # fmt: skip
        res = f.go_to(np.array([3.0, 0.0]))
    assert not res.reached and res.obstacles == 3
    events = list(read_log(tmp_path / "log.jsonl"))
    gave_up = [e for e in events if e.get("event") == "obstacle"][-1]["truth"]["truth_xy"]
    moved = math.hypot(robot.true[0] - gave_up[0], robot.true[1] - gave_up[1])
    assert robot.min_clearance >= robot.radius - 1e-9  # never drove through a wall
    if clear_m == 0:
        assert moved < 0.5 and not any(e.get("event") == "retrace_end" for e in events)
        return
    end = [e for e in events if e.get("event") == "retrace_end"][-1]
    assert end["stop"] == "clear" and end["moved_m"] >= 1.0
    assert moved >= 0.95 and robot.true[0] < 0.8  # out of the pocket, on its open side


class CountingPredictor:
    """Test double of :class:`scenebot.capture.predict.MatchPredictor`: map points a photo
    could match, by the robot's estimated heading (facing +y: a bare wall)."""

    def __init__(self):
        self.asked = []

    def __call__(self, pose):
        self.asked.append(pose)
        return 0 if math.sin(pose.theta) > 0.9 else 500


def test_no_photo_is_taken_where_the_map_predicts_nothing_to_match(tmp_path):
    """follow.min_matchable_points: facing the bare wall the robot takes no localization
    photo (logged localize_skipped, counted apart from the failures) and dead-reckons; its
    first localization of the round is taken whatever the prediction (no fix yet, the
    estimate may be anywhere); 0 turns the gate off."""
    path = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]])
    runs = {}
    for need in (10, 0):
        robot = KinematicRobot((0.0, 0.0, math.pi / 2), turn_slip=0.05)
        camera, pred = NullCamera(), CountingPredictor()
        cfg = FollowConfig(camera_forward_m=CAM_FWD, min_matchable_points=need)
        log_path = tmp_path / f"log_{need}.jsonl"
        with CaptureLog(log_path) as log:
            f = PathFollower(
                robot, camera, OracleLocalizer(robot), GridPlanner(_open_grid(), SIMPLIFY),
                cfg, tmp_path, log, initial_pose=Pose2D(0.0, 0.0, math.pi / 2),
                trust_initial=False, predictor=pred,
            )  # fmt: skip
            first = f.localize_now()  # facing the wall, but no fix yet: taken
            res = f.follow(path)
        events = [r for r in read_log(log_path) if r.get("type") == "event"]
        runs[need] = (res, camera.shots, events, pred)
        assert first.ok and res.reached
        assert math.hypot(robot.true[0] - 2.0, robot.true[1] - 2.0) < 0.1
    res, shots, events, pred = runs[10]
    skipped = [e for e in events if e["event"] == "localize_skipped"]
    assert skipped and res.skipped_localizations == len(skipped)
    assert all(e["predicted_points"] == 0 and e["min_matchable_points"] == 10 for e in skipped)
    assert all(math.sin(e["estimate"]["theta"]) > 0.9 for e in skipped)  # only at the wall
    assert not [e for e in events if e["event"] == "localize_failed"]
    res0, shots0, _, pred0 = runs[0]
    assert not pred0.asked and res0.skipped_localizations == 0
    photo_events = ("localize", "localize_failed", "localize_rejected")
    taken = [e for e in events if e["event"] in photo_events]
    assert shots == len(taken) and shots < shots0  # a photo for every localization but those
