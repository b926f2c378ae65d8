"""The simulator backend of the robot boundary: :class:`SimRobot` and :class:`SimCamera`.

The robot controls the simulated wheels exactly as a motor controller would: it commands wheel
speeds, watches the encoders (tacho counts) to know when a motion is done, integrates them
into odometry, stops when a bumper closes, and declares a stall when the wheels stop making
progress. It never looks at the true pose.

The simulator's state between rounds (:func:`write_sim_state`, :func:`read_sim_state`): the
world's true robot pose at the end of a capture, ``sim_state.json`` in the capture folder, so
the next round's simulated world continues where this one stopped. It is physics state, like
the room itself; no decision reads it.
"""

from __future__ import annotations

import json
import math
import os
from collections import deque
from pathlib import Path

from scenebot.jpeg import store_photo
from scenebot.robot.base import (
    Camera,
    Health,
    MotionResult,
    MotionStatus,
    Pose2D,
    Robot,
    SensorReading,
)
from scenebot.sim.world import SimWorld


class SimRobot(Robot):
    """A differential-drive robot in a :class:`SimWorld`."""

    def __init__(self, world: SimWorld):
        self.world = world
        self.cfg = world.cfg
        self._tacho = world.tacho_deg
        self._odo = Pose2D(0.0, 0.0, math.radians(world.compass_deg()))

    @property
    def now(self) -> float:
        return self.world.t

    @property
    def odometry(self) -> Pose2D:
        return self._odo

    def _update_odometry(self) -> tuple[float, float]:
        """Integrate encoder deltas since the last call; return (ds, dtheta)."""
        tl, tr = self.world.tacho_deg
        dl = math.radians(tl - self._tacho[0]) * self.world.params.wheel_radius_m
        dr = math.radians(tr - self._tacho[1]) * self.world.params.wheel_radius_m
        self._tacho = (tl, tr)
        ds, dth = 0.5 * (dl + dr), (dr - dl) / self.world.params.wheel_base_m
        o = self._odo
        mid = o.theta + 0.5 * dth
        self._odo = Pose2D(
            o.x + ds * math.cos(mid), o.y + ds * math.sin(mid), (o.theta + dth) % (2 * math.pi)
        )
        return ds, dth

    def _move(self, left_deg: float, right_deg: float, speed_deg_s: float, check_bumper: int):
        """Turn the wheels by the given angles at ``speed_deg_s``; stop early on bump/stall.

        Args:
            check_bumper: +1 stops on the front bumper, -1 on the rear one, 0 on neither.
        """
        w = self.world
        dt = self.cfg.dt_s
        target = max(abs(left_deg), abs(right_deg))
        if target < 1e-9:
            return MotionResult(MotionStatus.COMPLETED)
        k = speed_deg_s / target
        t0 = w.t
        start = w.tacho_deg
        ds_total = dth_total = 0.0
        window = max(1, round(self.cfg.sensors.stall_window_s / dt))
        history: deque[float] = deque(maxlen=window + 1)
        status, bumper = MotionStatus.COMPLETED, None
        while True:
            front, rear = w.bumpers()
            if (check_bumper > 0 and front) or (check_bumper < 0 and rear):
                status, bumper = MotionStatus.BUMPED, "front" if front else "rear"
                break
            done = max(abs(w.tacho_deg[0] - start[0]), abs(w.tacho_deg[1] - start[1]))
            remaining = target - done
            if remaining <= 1e-6:
                break
            history.append(done)
            if (
                len(history) > window
                and history[-1] - history[0] < self.cfg.sensors.stall_min_progress_deg
            ):
                status = MotionStatus.STALLED
                break
            w.set_wheel_speeds(left_deg * k, right_deg * k)
            w.step(min(dt, remaining / speed_deg_s))
            ds, dth = self._update_odometry()
            ds_total += ds
            dth_total += dth
        w.set_wheel_speeds(0.0, 0.0)
        ds, dth = self._update_odometry()
        return MotionResult(status, ds_total + ds, dth_total + dth, bumper, w.t - t0)

    def drive(self, distance_m: float) -> MotionResult:
        deg = math.degrees(distance_m / self.world.params.wheel_radius_m)
        return self._move(deg, deg, self.cfg.body.drive_speed_deg_s, 1 if distance_m > 0 else -1)

    def turn(self, angle_rad: float) -> MotionResult:
        arc = angle_rad * self.world.params.wheel_base_m / 2
        deg = math.degrees(arc / self.world.params.wheel_radius_m)
        return self._move(-deg, deg, self.cfg.body.turn_speed_deg_s, 0)

    def stop(self) -> None:
        self.world.set_wheel_speeds(0.0, 0.0)

    def sense(self) -> SensorReading:
        front, rear = self.world.bumpers()
        return SensorReading(
            t=self.world.t,
            compass_deg=self.world.compass_deg(),
            ultrasonic_cm=self.world.ultrasonic_cm(),
            bump_front=front,
            bump_rear=rear,
            odometry=self._odo,
        )

    def health(self) -> Health:
        return Health(battery_mv=8000, link_ok=True)

    def truth_record(self) -> dict:
        """True pose for the capture log (evaluation only; never used for decisions)."""
        return self.world.truth_record()


class SimCamera(Camera):
    """The simulated camera: renders the world from the robot's true camera pose."""

    def __init__(self, world: SimWorld):
        self.world = world

    def capture(self, dest: Path, timeout_s: float | None = None) -> Path:
        """Render the photo and store it at ``dest`` (atomically, verified, never over an
        existing file: :func:`scenebot.jpeg.store_photo`, which raises
        :class:`~scenebot.jpeg.PhotoWriteError`)."""
        dest = Path(dest)
        dest.parent.mkdir(parents=True, exist_ok=True)
        store_photo(dest, self.world.render_jpeg)
        self.world.step(self.world.cfg.photo_time_s)
        return dest


SIM_STATE = "sim_state.json"


def read_sim_state(capture_dir: Path) -> Pose2D | None:
    """The simulated robot's true pose at the end of a capture, if that capture left one."""
    p = Path(capture_dir) / SIM_STATE
    if not p.exists():
        return None
    d = json.loads(p.read_text(encoding="utf-8"))["robot"]
    return Pose2D(float(d["x"]), float(d["y"]), float(d["theta"]))


def write_sim_state(capture_dir: Path, world) -> None:
    """Save the simulated world's true robot pose (physics state for the next round),
    atomically: a full disk leaves the earlier file or none, never a cut one. A real robot
    (``world`` None) leaves none."""
    if world is None:
        return
    p = world.truth_pose
    doc = {
        "note": "simulator physics state for the next round; never read by a decision",
        "robot": {"x": p.x, "y": p.y, "theta": p.theta},
        "t": world.t,
    }
    dest = Path(capture_dir) / SIM_STATE
    tmp = dest.with_name(f".{SIM_STATE}.{os.getpid()}.part")
    try:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(json.dumps(doc, indent=1))
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, dest)
    finally:
        tmp.unlink(missing_ok=True)
