"""Path following with visual localization (paper section IV.B, "Path-Following").

The robot keeps a target node of its path and switches to the next node when it comes within
``node_reached_m`` of it. Between visual fixes the pose is dead-reckoned from odometry
*relative to the last fix* (so the odometry frame's origin never matters), its heading
corrected by the compass after every motion (``compass_std_deg``); a photo is
localized at every node, after every large turn (slip happens mostly on turns) and after every
``localize_every_m`` of driving. When a bumper or a stall stops the robot, it backs up, drives
a short distance off the path, marks the obstacle on its planner and plans a new path; at the
``max_obstacles``-th obstacle it gives up on the goal, logging why, and retraces its own motions
backwards until it stands ``retrace_clear_m`` from where it gave up: a robot wedged in a corner
the map does not show leaves by the way it came in. A photo that does not
localize (too few matches or inliers, or a pose that is not that of a level camera on the
robot) leaves the odometry estimate in charge; the next motion is followed by another attempt,
and at the goal the robot turns in place to look elsewhere before retrying. A fix that jumps
far from the odometry prediction (repeated textures can give confident wrong poses) is
rejected unless the next fix, taken after a turn of ``override_min_turn_deg`` or more (another
view), agrees with it (``gate_m``, ``gate_deg``). A goal counts as
reached only on a *confirmed* fix: a second fix, taken from the same spot after a turn in place
(a different view of the map), must agree with the first within ``confirm_m``. One wrong fix in
a poorly textured corner then cannot end the approach ``goal_reached_m`` off; when no second
fix comes within ``max_localize_retries`` attempts the goal is accepted as it stands and
reported unconfirmed (``confirmed_at_goal``).

Everything runs against :class:`scenebot.robot.base.Robot` and :class:`Camera`; localization
and planning are injected callables, so the same code runs on the simulator and on hardware.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scenebot.capturelog import CaptureLog
from scenebot.config import FollowConfig
from scenebot.localize.locate import FailureReason, LocalizationFailure, PoseEstimate
from scenebot.plan.path import PlanFailure, PlannedPath
from scenebot.robot.base import Camera, MotionResult, MotionStatus, Pose2D, Robot, wrap_angle

Localizer = Callable[[Path], PoseEstimate | LocalizationFailure]
Planner = Callable[[np.ndarray, np.ndarray], PlannedPath | PlanFailure]


def robot_pose_from_camera(est: PoseEstimate, forward_m: float, left_m: float) -> Pose2D:
    """The robot's planar pose (rotation axis, heading) from a camera pose estimate."""
    c = est.center
    th = est.heading
    x = c[0] - forward_m * math.cos(th) + left_m * math.sin(th)
    y = c[1] - forward_m * math.sin(th) - left_m * math.cos(th)
    return Pose2D(float(x), float(y), th % (2 * math.pi))


def compose_odometry(fix: Pose2D, odo_at_fix: Pose2D, odo_now: Pose2D) -> Pose2D:
    """Map pose now = the fix composed with the odometry motion since the fix.

    Args:
        fix: map-frame pose at the fix.
        odo_at_fix: odometry reading at the fix.
        odo_now: odometry reading now.
    """
    dx, dy = odo_now.x - odo_at_fix.x, odo_now.y - odo_at_fix.y
    c, s = math.cos(odo_at_fix.theta), math.sin(odo_at_fix.theta)
    fwd, left = c * dx + s * dy, -s * dx + c * dy  # motion in the body frame at the fix
    cf, sf = math.cos(fix.theta), math.sin(fix.theta)
    dth = wrap_angle(odo_now.theta - odo_at_fix.theta)
    return Pose2D(
        fix.x + cf * fwd - sf * left,
        fix.y + sf * fwd + cf * left,
        (fix.theta + dth) % (2 * math.pi),
    )


@dataclass
class FollowResult:
    """The outcome of going to one goal.

    Attributes:
        reached: the goal was reached within ``goal_reached_m`` (by a visual fix, or by
            odometry when ``localized_at_goal`` is False).
        reason: ``"reached"`` or why the goal was abandoned.
        pose: final estimated map pose.
        distance_m: estimated distance from the goal at the end (m).
        obstacles: bumps/stalls met.
        localizations: successful visual fixes; ``failed_localizations``: failed ones;
            ``skipped_localizations``: photos not taken, the map predicting too few matches.
        localized_at_goal: the final pose comes from a fix taken at the goal.
        confirmed_at_goal: and a second fix from the same spot agreed with it (``confirm_m``).
        goal_xy: the robot position driven to (m, map frame): the requested goal, or where
            the planner moved it off an obstacle cell.
        motions: motion commands issued.
        replans: paths planned after obstacles.
    """

    reached: bool
    reason: str
    pose: Pose2D
    distance_m: float
    obstacles: int = 0
    localizations: int = 0
    failed_localizations: int = 0
    skipped_localizations: int = 0
    localized_at_goal: bool = False
    confirmed_at_goal: bool = False
    goal_xy: tuple[float, float] | None = None
    motions: int = 0
    replans: int = 0
    events: list = field(default_factory=list)

    def as_record(self) -> dict:
        return {
            "reached": self.reached,
            "reason": self.reason,
            "pose": self.pose.as_dict(),
            "distance_m": self.distance_m,
            "obstacles": self.obstacles,
            "localizations": self.localizations,
            "failed_localizations": self.failed_localizations,
            "skipped_localizations": self.skipped_localizations,
            "localized_at_goal": self.localized_at_goal,
            "confirmed_at_goal": self.confirmed_at_goal,
            "goal_xy": None if self.goal_xy is None else list(self.goal_xy),
            "motions": self.motions,
            "replans": self.replans,
        }


class _GiveUp(Exception):
    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


class PathFollower:
    """Drives a robot along planned paths, localizing visually (see the module docstring).

    Args:
        robot: the robot.
        camera: its camera.
        localizer: photo path -> pose estimate or failure (e.g. a closure over
            :func:`scenebot.localize.locate` and a loaded map).
        planner: (start_xy, goal_xy) -> path or failure; if it has ``mark_obstacle(xy, r)``
            (:class:`scenebot.plan.path.GridPlanner`), bumps are marked on its grid.
        cfg: follow settings.
        photo_dir: where localization photos are written.
        log: capture log for events (optional).
        truth: simulator only: returns the true pose record for the log (never used to
            decide anything).
        initial_pose: map pose to assume until the first successful fix.
        trust_initial: gate the first fix against ``initial_pose`` (False: accept any first
            fix, e.g. when the robot may have moved since ``initial_pose`` was known).
        predictor: map pose -> map points a photo from there could match
            (:class:`scenebot.capture.predict.MatchPredictor`); None: every localization
            takes its photo.
    """

    TRAIL_LENGTH = 400  # motions kept for retracing

    def __init__(
        self,
        robot: Robot,
        camera: Camera,
        localizer: Localizer,
        planner: Planner,
        cfg: FollowConfig | None = None,
        photo_dir: Path = Path("nav"),
        log: CaptureLog | None = None,
        truth: Callable[[], dict] | None = None,
        initial_pose: Pose2D | None = None,
        trust_initial: bool = True,
        predictor: Callable[[Pose2D], int] | None = None,
    ):
        self.robot = robot
        self.predictor = predictor
        self.camera = camera
        self.localizer = localizer
        self.planner = planner
        self.cfg = cfg or FollowConfig()
        self.photo_dir = Path(photo_dir)
        self.log = log
        self.truth = truth
        odo = robot.sense().odometry
        # dead reckoning: map pose self._dr at odometry reading self._odo_dr, heading
        # variance self._hvar (rad^2); the compass corrects the heading only once the pose
        # is in the map frame (an initial pose or a fix)
        self._dr = initial_pose or odo
        self._odo_dr = odo
        self._in_map = initial_pose is not None
        self._hvar = math.radians(2.0) ** 2 if trust_initial else math.pi**2
        self.compass_updates = 0
        self.compass_rejected = 0
        self._since_fix_m = 0.0 if initial_pose is not None and trust_initial else math.inf
        self._photo_count = 0
        self._rejected: tuple[Pose2D, Pose2D] | None = None  # (fix, odometry) last rejected
        self._fixes_here: list[Pose2D] = []  # fixes since the robot last drove
        self._goal_index = 0
        self._result: FollowResult | None = None
        # the latest motions, as the encoders counted them, for retracing
        self._trail: deque[tuple[str, float]] = deque(maxlen=self.TRAIL_LENGTH)

    # ------------------------------------------------------------------ state
    @property
    def pose(self) -> Pose2D:
        """Current map pose estimate (last fix, dead-reckoned since; see :meth:`_dead_reckon`)."""
        return compose_odometry(self._dr, self._odo_dr, self.robot.sense().odometry)

    def _dead_reckon(self, turned_rad: float = 0.0) -> None:
        """Advance the dead-reckoned pose to the current odometry and correct its heading
        with the compass (1-D Kalman filter on the heading).

        The heading's variance grows with the odometry turn (``turn_slip_std``, relative)
        and the distance driven (``heading_drift_deg_per_m``); a compass reading within 3
        sigma of the prediction pulls the heading towards it by the Kalman gain. Slip on
        turns is what makes dead reckoning drift: a 90 deg turn slipping 8 % points the
        robot 7 deg off, 6 cm sideways after half a metre, while the compass reads within a
        degree or two.
        """
        cfg = self.cfg
        reading = self.robot.sense()
        odo = reading.odometry
        # the turn as the encoders counted it (a turn beyond 180 deg wraps in odometry)
        turn = max(abs(turned_rad), abs(wrap_angle(odo.theta - self._odo_dr.theta)))
        dist = math.hypot(odo.x - self._odo_dr.x, odo.y - self._odo_dr.y)
        pred = compose_odometry(self._dr, self._odo_dr, odo)
        self._hvar += (cfg.turn_slip_std * turn) ** 2
        self._hvar += (math.radians(cfg.heading_drift_deg_per_m) * dist) ** 2
        theta = pred.theta
        c = reading.compass_deg
        if self._in_map and cfg.compass_std_deg > 0 and c is not None and math.isfinite(c):
            r = math.radians(cfg.compass_std_deg) ** 2
            innov = wrap_angle(math.radians(c) - pred.theta)
            if innov**2 <= 9.0 * (self._hvar + r):
                k = self._hvar / (self._hvar + r)
                theta = (pred.theta + k * innov) % (2 * math.pi)
                self._hvar *= 1.0 - k
                self.compass_updates += 1
            else:
                self.compass_rejected += 1
        self._dr = Pose2D(pred.x, pred.y, theta)
        self._odo_dr = odo

    def _set_fix(self, fix: Pose2D, odo: Pose2D, heading_std_deg: float = 0.5) -> None:
        """A visual fix becomes the dead-reckoning origin."""
        self._dr = fix
        self._odo_dr = odo
        self._in_map = True
        self._hvar = math.radians(heading_std_deg) ** 2

    def _event(self, event: str, **fields) -> None:
        rec = {
            "type": "event",
            "t": self.robot.now,
            "event": event,
            "goal_index": self._goal_index,
            "odometry": self.robot.sense().odometry.as_dict(),
            "estimate": self.pose.as_dict(),
            **fields,
        }
        if self.truth is not None:
            rec["truth"] = self.truth()
        if self._result is not None:
            self._result.events.append(rec)
        if self.log is not None:
            self.log.write(rec)

    def _log_name(self, path: Path) -> str:
        """A photo's path as the log records it: relative to the log's folder (the capture
        folder) when inside it, so that an archived log points at its archived photos."""
        if self.log is not None:
            try:
                return Path(path).resolve().relative_to(self.log.path.parent.resolve()).as_posix()
            except ValueError:
                pass
        return str(path)

    def localize_now(self) -> PoseEstimate | LocalizationFailure:
        """Take a photo and localize it; on success it becomes the new fix. No photo where
        the map predicts fewer than ``min_matchable_points`` matches from the pose estimate
        (once the robot has had a fix): :meth:`_predicted_unmatchable`."""
        skip = self._predicted_unmatchable()
        if skip is not None:
            return skip
        dest = self.photo_dir / f"nav_g{self._goal_index:03d}_{self._photo_count:04d}.jpg"
        self._photo_count += 1
        reading = self.robot.sense()
        path = self.camera.capture(dest)
        return self.localize_photo(path, reading.odometry, reading.compass_deg)

    def _predicted_unmatchable(self) -> LocalizationFailure | None:
        """A failure (logged ``localize_skipped``) when the ``predictor`` counts fewer than
        ``min_matchable_points`` map points the camera could match from the pose estimate;
        None when a photo is worth taking (or there is no predictor, the gate is off, or no
        fix yet: before the first fix the estimate may be anywhere)."""
        need = self.cfg.min_matchable_points
        if self.predictor is None or need <= 0 or not math.isfinite(self._since_fix_m):
            return None
        n = int(self.predictor(self.pose))
        if n >= need:
            return None
        if self._result is not None:
            self._result.skipped_localizations += 1
        self._event("localize_skipped", predicted_points=n, min_matchable_points=need)
        return LocalizationFailure(FailureReason.PREDICTED_UNMATCHABLE)

    def localize_photo(
        self, path: Path, odo: Pose2D, compass_deg: float | None = None
    ) -> PoseEstimate | LocalizationFailure:
        """Localize a photo taken at odometry ``odo``; a consistent fix becomes the new fix.

        Args:
            path: the photo.
            odo: the odometry reading when it was taken.
            compass_deg: the compass reading then (None: no compass check).
        """
        est = self.localizer(path)
        res = self._result
        if est.ok:
            cand = robot_pose_from_camera(est, self.cfg.camera_forward_m, self.cfg.camera_left_m)
            off = self._compass_disagreement_deg(cand, compass_deg)
            if off is not None:
                return self._reject(
                    path, FailureReason.INCONSISTENT_WITH_COMPASS, cand, est,
                    compass_deg=compass_deg, heading_off_deg=off,
                )  # fmt: skip
            if not self._consistent(cand, odo):
                self._rejected = (cand, odo)
                return self._reject(path, FailureReason.INCONSISTENT_WITH_ODOMETRY, cand, est)
            self._rejected = None
            self._set_fix(cand, odo)
            self._fixes_here.append(cand)
            self._since_fix_m = 0.0
            if res is not None:
                res.localizations += 1
            self._event("localize", image=self._log_name(path), localization=est.as_record())
        else:
            if res is not None:
                res.failed_localizations += 1
            self._event("localize_failed", image=self._log_name(path), localization=est.as_record())
        return est

    def _reject(self, path: Path, reason: FailureReason, cand: Pose2D, est: PoseEstimate,
                **fields) -> LocalizationFailure:  # fmt: skip
        """Log a fix that is not used (``localize_rejected``) and return it as a failure."""
        if self._result is not None:
            self._result.failed_localizations += 1
        self._event("localize_rejected", image=self._log_name(path), reason=str(reason), **fields,
                    candidate=cand.as_dict(), localization=est.as_record())  # fmt: skip
        return LocalizationFailure(
            reason, est.num_features, est.num_matches, est.num_inliers, est.timings_s
        )

    def _compass_disagreement_deg(self, cand: Pose2D, compass_deg: float | None) -> float | None:
        """How far (deg) a fix's heading is from the compass when beyond ``compass_gate_deg``,
        else None. The map's x axis is compass heading 0 (see :mod:`scenebot.sfm.align`)."""
        gate = self.cfg.compass_gate_deg
        if gate <= 0 or compass_deg is None or not math.isfinite(compass_deg):
            return None
        off = abs(math.degrees(wrap_angle(cand.theta - math.radians(compass_deg))))
        return off if off > gate else None

    def _consistent(self, cand: Pose2D, odo: Pose2D) -> bool:
        """Whether a fix agrees with the odometry prediction, or with the last rejected fix
        carried forward by odometry when the robot turned by ``override_min_turn_deg`` or
        more since (two agreeing fixes of different views override the prediction)."""
        cfg = self.cfg
        allowed = cfg.gate_m + cfg.gate_per_m * self._since_fix_m
        if not math.isfinite(allowed):
            return True  # no prior yet: nothing to check against

        def close(a: Pose2D, b: Pose2D, tol_m: float) -> bool:
            dth = abs(math.degrees(wrap_angle(a.theta - b.theta)))
            return math.hypot(a.x - b.x, a.y - b.y) <= tol_m and dth <= cfg.gate_deg

        if close(cand, compose_odometry(self._dr, self._odo_dr, odo), allowed):
            return True
        if self._rejected is not None:
            prev, prev_odo = self._rejected
            turned = abs(math.degrees(wrap_angle(odo.theta - prev_odo.theta)))
            return turned >= cfg.override_min_turn_deg and close(
                cand, compose_odometry(prev, prev_odo, odo), cfg.gate_m
            )
        return False

    def _confirmed_here(self) -> bool:
        """Whether the last fix is confirmed: an earlier fix since the robot last drove (only
        turns in place between them, which leave the rotation axis where it was) puts the
        robot within ``confirm_m`` of it. ``confirm_m`` 0: any fix is confirmed."""
        if self.cfg.confirm_m <= 0:
            return bool(self._fixes_here)
        if len(self._fixes_here) < 2:
            return False
        last = self._fixes_here[-1]
        return any(
            math.hypot(f.x - last.x, f.y - last.y) <= self.cfg.confirm_m
            for f in self._fixes_here[:-1]
        )

    def _motion(self, kind: str, amount: float) -> MotionResult:
        res = self._result
        if res is not None:
            res.motions += 1
            if res.motions > self.cfg.max_motions:
                raise _GiveUp(f"more than {self.cfg.max_motions} motion commands for this goal")
        r = self._move(kind, amount)
        self._trail.append((kind, r.distance_m if kind == "drive" else r.angle_rad))
        if r.status is MotionStatus.LINK_LOST:
            raise _GiveUp("link to the robot lost during a motion")
        return r

    def _move(self, kind: str, amount: float) -> MotionResult:
        """Drive or turn, and advance the dead reckoning (no goal bookkeeping)."""
        r = self.robot.drive(amount) if kind == "drive" else self.robot.turn(amount)
        self._dead_reckon(r.angle_rad if kind == "turn" else 0.0)
        if kind == "drive":
            self._since_fix_m += abs(r.distance_m)
            self._fixes_here.clear()
        return r

    # ------------------------------------------------------------------ obstacles

    def retrace(self) -> float:
        """Drive the recorded motions backwards, latest first, until the robot stands
        ``retrace_clear_m`` (odometry) from where it started retracing, or has driven
        ``retrace_max_m``, or a bumper stops it; then localize.

        The motions brought the robot here through space it could drive, so undoing them
        leaves a corner the map does not show by the way it came in, whatever the map and
        the pose estimate say. Undone motions leave the trail.

        Returns:
            The distance driven (m).
        """
        cfg = self.cfg
        if cfg.retrace_clear_m <= 0 or not self._trail:
            return 0.0
        start = self.robot.sense().odometry
        driven, motions, stop = 0.0, 0, "trail exhausted"
        self._event("retrace_start", trail=len(self._trail))
        while self._trail:
            o = self.robot.sense().odometry
            if math.hypot(o.x - start.x, o.y - start.y) >= cfg.retrace_clear_m:
                stop = "clear"
                break
            kind, amount = self._trail[-1]
            if kind == "drive" and driven + abs(amount) > cfg.retrace_max_m:
                stop = f"retrace_max_m ({cfg.retrace_max_m} m)"
                break
            self._trail.pop()
            if abs(amount) < 1e-6:
                continue
            r = self._move(kind, -amount)
            motions += 1
            driven += abs(r.distance_m)
            if r.interrupted:
                stop = f"{r.status} ({r.bumper or 'no'} bumper)"
                break
        o = self.robot.sense().odometry
        self._event("retrace_end", motions=motions, driven_m=driven, stop=stop,
                    moved_m=math.hypot(o.x - start.x, o.y - start.y))  # fmt: skip
        if motions:
            self.localize_now()
        return driven

    def _handle_obstacle(self, r: MotionResult, goal_xy: np.ndarray) -> PlannedPath:
        res = self._result
        assert res is not None
        res.obstacles += 1
        p = self.pose
        contact = np.array(
            [
                p.x + self.cfg.contact_distance_m * math.cos(p.theta),
                p.y + self.cfg.contact_distance_m * math.sin(p.theta),
            ]
        )
        self._event("obstacle", status=str(r.status), bumper=r.bumper, count=res.obstacles)
        if res.obstacles >= self.cfg.max_obstacles:
            raise _GiveUp(
                f"{res.obstacles} obstacles met on the way (max_obstacles = "
                f"{self.cfg.max_obstacles}): the map cannot route to this goal"
            )
        mark = getattr(self.planner, "mark_obstacle", None)
        if mark is not None:
            mark(contact, self.cfg.obstacle_radius_m)
        # Back up, then drive a short distance off the path (alternating sides).
        self._motion("drive", -self.cfg.backup_m)
        side = 1.0 if res.obstacles % 2 else -1.0
        if self.cfg.sidestep_m > 0:
            self._motion("turn", side * math.pi / 2)
            self._motion("drive", self.cfg.sidestep_m)  # a bump here is met again later
        self.localize_now()
        plan = self.planner(np.array([self.pose.x, self.pose.y]), goal_xy)
        res.replans += 1
        if isinstance(plan, PlanFailure):
            raise _GiveUp(f"replanning failed: {plan.message}")
        self._event("replan", waypoints=plan.waypoints_xy.tolist())
        return plan

    # ------------------------------------------------------------------ main loop
    def follow(
        self,
        path_xy: np.ndarray,
        goal_theta: float | None = None,
        goal_index: int = 0,
    ) -> FollowResult:
        """Follow ``path_xy`` (M, 2) (m, map frame) to its last node.

        Args:
            path_xy: waypoints; the first is the planned start (skipped), the last the goal.
            goal_theta: heading (rad) to turn to at the goal, if any.
            goal_index: index of the goal, for photo names and log events.

        Returns:
            The outcome (never raises for bumps, stalls or failed localizations).
        """
        cfg = self.cfg
        path = np.asarray(path_xy, float).reshape(-1, 2)
        goal = path[-1].copy()
        self._goal_index = goal_index
        res = self._result = FollowResult(False, "", self.pose, math.inf)
        self.compass_updates = self.compass_rejected = 0  # per goal, in follow_end
        self._event("follow_start", goal=goal.tolist(), waypoints=path.tolist())
        retries = 0
        try:
            if self._since_fix_m > 0:
                self.localize_now()
            target = 1 if len(path) > 1 else 0
            while True:
                p = self.pose
                here = np.array([p.x, p.y])
                while (
                    target < len(path) - 1 and np.hypot(*(path[target] - here)) < cfg.node_reached_m
                ):
                    target += 1
                    self._event("target_node", node=target, xy=path[target].tolist())
                d_goal = float(np.hypot(*(goal - here)))
                if target == len(path) - 1 and d_goal < cfg.goal_reached_m:
                    if self._since_fix_m == 0.0 and self._confirmed_here():
                        break  # two fixes taken here agree
                    if retries > cfg.max_localize_retries:
                        break  # accept it, reported by localized/confirmed_at_goal
                    if retries > 0 or self._since_fix_m == 0.0:
                        # look elsewhere first: after a failed fix, or for a second opinion
                        # on a fix taken here (a different view of the map)
                        if cfg.retry_turn_deg > 0:  # sweep around in small turns
                            self._motion("turn", math.radians(cfg.retry_turn_deg))
                        else:
                            self._motion("drive", -cfg.retry_move_m)
                    retries += 1
                    self.localize_now()
                    continue  # re-check with the fix (or the odometry)
                tgt = path[target]
                turn = wrap_angle(math.atan2(tgt[1] - here[1], tgt[0] - here[0]) - p.theta)
                if abs(math.degrees(turn)) > cfg.min_turn_deg:
                    self._motion("turn", turn)
                    if abs(math.degrees(turn)) > cfg.localize_after_turn_deg:
                        self.localize_now()
                        continue  # the fix may change the heading to steer
                p = self.pose
                dist = float(np.hypot(tgt[0] - p.x, tgt[1] - p.y))
                step = min(dist, cfg.localize_every_m)
                r = self._motion("drive", step)
                if r.status in (MotionStatus.BUMPED, MotionStatus.STALLED):
                    plan = self._handle_obstacle(r, goal)
                    path = plan.waypoints_xy
                    goal = path[-1].copy()  # the planner may move a goal off a marked obstacle
                    target = 1 if len(path) > 1 else 0
                    continue
                at_node = step >= dist - 1e-9
                if at_node or self._since_fix_m >= cfg.localize_every_m:
                    self.localize_now()
            res.reached = True
            res.reason = "reached"
            res.localized_at_goal = self._since_fix_m == 0.0
            res.confirmed_at_goal = res.localized_at_goal and self._confirmed_here()
            if goal_theta is not None and cfg.turn_to_goal_heading:
                for _ in range(3):  # turn, check the heading with a fix, correct the slip
                    turn = wrap_angle(goal_theta - self.pose.theta)
                    if abs(math.degrees(turn)) <= cfg.min_turn_deg:
                        break
                    self._motion("turn", turn)
                    self.localize_now()
        except _GiveUp as g:
            res.reached = False
            res.reason = g.reason
            if res.obstacles > 0 and "link" not in g.reason:
                self.retrace()
        p = self.pose
        res.pose = p
        res.goal_xy = (float(goal[0]), float(goal[1]))
        res.distance_m = float(np.hypot(goal[0] - p.x, goal[1] - p.y))
        self._event(
            "follow_end",
            **res.as_record(),
            compass_updates=self.compass_updates,
            compass_rejected=self.compass_rejected,
        )
        self._result = None
        return res

    def go_to(self, goal_xy: np.ndarray, goal_theta: float | None = None, goal_index: int = 0):
        """Plan from the current pose estimate to ``goal_xy`` and follow the path.

        Returns:
            A :class:`FollowResult`; a goal that cannot be planned to is abandoned with the
            planner's reason.
        """
        self._goal_index = goal_index
        if self._since_fix_m > 0:
            self.localize_now()
        p = self.pose
        plan = self.planner(np.array([p.x, p.y]), np.asarray(goal_xy, float))
        if isinstance(plan, PlanFailure):
            res = FollowResult(False, f"skipped: {plan.message}", p, math.inf)
            self._event("no_route", reason=str(plan.reason), message=plan.message)
            return res
        return self.follow(plan.waypoints_xy, goal_theta, goal_index)

    def go_to_view(self, camera_xy: np.ndarray, heading: float, goal_index: int = 0):
        """Go where the camera centre lands on ``camera_xy`` facing ``heading`` (a goals.json
        goal: camera centre x, y in m and heading theta in rad)."""
        c, s = math.cos(heading), math.sin(heading)
        fwd, left = self.cfg.camera_forward_m, self.cfg.camera_left_m
        robot_xy = np.asarray(camera_xy, float) - np.array([fwd * c - left * s, fwd * s + left * c])
        return self.go_to(robot_xy, heading, goal_index)
