"""The robot boundary: one interface, several backends (DESIGN.md section 3).

Exploration and path following are written once against :class:`Robot` and :class:`Camera`.
Backends: ``sim`` (:mod:`scenebot.robot.sim`), ``nxt`` (a LEGO NXT over a Bluetooth serial
port) and the NXT driver against the brick emulator on a pseudo-terminal.

Conventions (all backends):

* Lengths in metres, angles in radians unless a name says ``_deg``; time in seconds.
* The **odometry frame** starts at ``x = y = 0`` with ``theta`` equal to the first compass
  heading, so odometry headings and compass headings share one reference ("magnetic north"),
  and the odometry origin is where the robot was switched on.
* Headings are counter-clockwise, in ``[0, 2 pi)`` for odometry and ``[0, 360)`` degrees for
  the compass (the NXT backend converts clockwise sensors).
* A motion command blocks until the motion has finished or was interrupted, and returns a
  :class:`MotionResult` that says what happened. Motions never raise for bumps or stalls:
  those are normal events of exploration. They raise :class:`RobotError` subclasses for
  faults the caller cannot handle in the control loop (link lost for good, battery flat).
"""

from __future__ import annotations

import abc
import enum
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

ULTRASONIC_NO_ECHO_CM = 255
"""Raw ultrasonic reading meaning "no echo within range" (LEGO convention)."""


class RobotError(RuntimeError):
    """A robot fault that stops the current campaign step (the message says what to check)."""


class LinkLostError(RobotError):
    """The link to the robot is gone and could not be re-established."""


class BatteryLowError(RobotError):
    """The robot's battery is below the configured minimum."""


class CameraError(RobotError):
    """The camera did not deliver a usable photo in time."""


class MotionStatus(enum.StrEnum):
    """How a motion command ended."""

    COMPLETED = "completed"
    BUMPED = "bumped"
    STALLED = "stalled"
    LINK_LOST = "link_lost"


@dataclass(frozen=True)
class Pose2D:
    """A planar pose: position (m) and heading (rad, counter-clockwise from the x axis)."""

    x: float
    y: float
    theta: float

    def as_dict(self) -> dict[str, float]:
        return {"x": self.x, "y": self.y, "theta": self.theta}

    @staticmethod
    def from_dict(d: dict[str, float]) -> Pose2D:
        return Pose2D(float(d["x"]), float(d["y"]), float(d["theta"]))


def wrap_angle(a: float) -> float:
    """Wrap an angle (rad) into ``(-pi, pi]``."""
    a = math.fmod(a + math.pi, 2.0 * math.pi)
    if a <= 0.0:
        a += 2.0 * math.pi
    return a - math.pi


@dataclass(frozen=True)
class MotionResult:
    """What a motion command did.

    Attributes:
        status: how it ended.
        distance_m: signed distance driven according to the wheel encoders (odometry).
        angle_rad: signed rotation according to the wheel encoders (odometry).
        bumper: ``"front"`` or ``"rear"`` when a bumper stopped the motion, else ``None``.
        duration_s: time the motion took.
    """

    status: MotionStatus
    distance_m: float = 0.0
    angle_rad: float = 0.0
    bumper: str | None = None
    duration_s: float = 0.0

    @property
    def interrupted(self) -> bool:
        return self.status is not MotionStatus.COMPLETED


@dataclass(frozen=True)
class SensorReading:
    """One reading of all sensors.

    Attributes:
        t: robot clock (s).
        compass_deg: heading, counter-clockwise, ``[0, 360)``.
        ultrasonic_cm: range in whole centimetres; ``ULTRASONIC_NO_ECHO_CM`` (255) = no echo.
        bump_front, bump_rear: bumper switches pressed.
        odometry: dead-reckoned pose in the odometry frame.
    """

    t: float
    compass_deg: float
    ultrasonic_cm: int
    bump_front: bool
    bump_rear: bool
    odometry: Pose2D

    def as_record(self) -> dict:
        d = asdict(self)
        d["odometry"] = self.odometry.as_dict()
        return d


@dataclass(frozen=True)
class Health:
    """Robot health: battery (mV, ``None`` if unknown) and whether the link is up."""

    battery_mv: int | None
    link_ok: bool
    details: dict = field(default_factory=dict)


class Robot(abc.ABC):
    """A differential-drive robot with compass, ultrasonic rangefinder and two bumpers."""

    @abc.abstractmethod
    def drive(self, distance_m: float) -> MotionResult:
        """Drive straight ``distance_m`` (negative: backwards); stops early on bump or stall."""

    @abc.abstractmethod
    def turn(self, angle_rad: float) -> MotionResult:
        """Turn in place by ``angle_rad`` (positive: counter-clockwise)."""

    @abc.abstractmethod
    def stop(self) -> None:
        """Stop all motors now. Safe to call at any time, repeatedly."""

    @abc.abstractmethod
    def sense(self) -> SensorReading:
        """Read all sensors once."""

    @abc.abstractmethod
    def health(self) -> Health:
        """Battery and link state."""

    @property
    @abc.abstractmethod
    def now(self) -> float:
        """The robot's clock in seconds (simulated time for the simulator)."""

    def turn_to_heading(self, heading_deg: float, tolerance_deg: float = 2.0) -> MotionResult:
        """Turn until the compass reads ``heading_deg`` (two corrective steps at most)."""
        result = MotionResult(MotionStatus.COMPLETED)
        total = 0.0
        for _ in range(3):
            error = wrap_angle(math.radians(heading_deg - self.sense().compass_deg))
            if abs(math.degrees(error)) <= tolerance_deg:
                break
            result = self.turn(error)
            total += result.angle_rad
            if result.interrupted:
                break
        return MotionResult(result.status, 0.0, total, result.bumper, result.duration_s)

    def close(self) -> None:
        """Stop the motors and release the link. Called on every exit path."""
        self.stop()

    def __enter__(self) -> Robot:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class Camera(abc.ABC):
    """A camera that delivers finished JPEG files."""

    @abc.abstractmethod
    def capture(self, dest: Path, timeout_s: float | None = None) -> Path:
        """Take a photo and store it at ``dest`` (a ``.jpg`` path); return the path.

        ``timeout_s``: how long to wait for the photo (s); None: the backend's configured
        timeout (``nxt.camera.timeout_s``; the simulator's photo is there at once).

        Raises:
            CameraError: no usable photo arrived within ``timeout_s``.
        """

    def close(self) -> None:  # noqa: B027 (optional hook, nothing to release by default)
        """Release the camera (switch off the trigger line)."""
