"""A minimal stand-in for the simulator: a robot in an empty rectangular room.

It implements the world API the brick emulator drives (:class:`scenebot.robot.nxt.emulator.
World`) with simple but physical behaviour, so the NXT driver can be tested without the full
simulator: differential drive from wheel speeds, a circular footprint that cannot enter the
walls (a wheel pushing into a wall is blocked and its encoder stops), front/rear bumpers, an
ultrasonic ray to the nearest wall (255 beyond ``us_max_cm``), a counter-clockwise compass, and
a photo (a JPEG whose content depends on the pose) for the camera.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from scenebot.robot.base import Pose2D


@dataclass(frozen=True)
class BoxParams:
    wheel_radius_m: float = 0.028
    wheel_base_m: float = 0.12
    max_wheel_speed_deg_s: float = 720.0
    half_x_m: float = 1.5
    half_y_m: float = 1.0
    robot_radius_m: float = 0.12
    us_max_cm: int = 200
    photo_px: tuple[int, int] = (160, 120)


class BoxWorld:
    """Robot in a ``2 half_x x 2 half_y`` m room centred at the origin.

    Args:
        params: geometry.
        pose: start pose (m, rad).
    """

    def __init__(self, params: BoxParams | None = None, pose: Pose2D | None = None):
        self.params = params or BoxParams()
        self.truth_pose = pose or Pose2D(0.0, 0.0, 0.0)
        self.t = 0.0
        self._speeds = (0.0, 0.0)
        self._tacho = [0.0, 0.0]
        self.photos = 0

    @property
    def tacho_deg(self) -> tuple[float, float]:
        return (self._tacho[0], self._tacho[1])

    def set_wheel_speeds(self, left_deg_s: float, right_deg_s: float) -> None:
        m = self.params.max_wheel_speed_deg_s
        self._speeds = (max(-m, min(m, left_deg_s)), max(-m, min(m, right_deg_s)))

    def _inside(self, x: float, y: float) -> bool:
        p = self.params
        r = p.robot_radius_m
        return abs(x) <= p.half_x_m - r and abs(y) <= p.half_y_m - r

    def step(self, dt: float) -> None:
        p = self.params
        wl, wr = self._speeds
        dl = math.radians(wl * dt) * p.wheel_radius_m
        dr = math.radians(wr * dt) * p.wheel_radius_m
        ds, dth = 0.5 * (dl + dr), (dr - dl) / p.wheel_base_m
        q = self.truth_pose
        mid = q.theta + 0.5 * dth
        x, y = q.x + ds * math.cos(mid), q.y + ds * math.sin(mid)
        if self._inside(x, y):
            self.truth_pose = Pose2D(x, y, (q.theta + dth) % (2 * math.pi))
            self._tacho[0] += wl * dt
            self._tacho[1] += wr * dt
        elif abs(ds) < 1e-12:
            self.truth_pose = Pose2D(q.x, q.y, (q.theta + dth) % (2 * math.pi))
            self._tacho[0] += wl * dt
            self._tacho[1] += wr * dt
        # else: blocked by a wall; wheels do not turn, encoders stay
        self.t += dt

    def _wall_distance(self, heading: float) -> float:
        p, q = self.params, self.truth_pose
        c, s = math.cos(heading), math.sin(heading)
        ds = []
        if c > 1e-9:
            ds.append((p.half_x_m - q.x) / c)
        if c < -1e-9:
            ds.append((-p.half_x_m - q.x) / c)
        if s > 1e-9:
            ds.append((p.half_y_m - q.y) / s)
        if s < -1e-9:
            ds.append((-p.half_y_m - q.y) / s)
        return min(ds)

    def bumpers(self) -> tuple[bool, bool]:
        r = self.params.robot_radius_m
        th = self.truth_pose.theta
        front = self._wall_distance(th) <= r + 0.01
        rear = self._wall_distance(th + math.pi) <= r + 0.01
        return front, rear

    def ultrasonic_cm(self) -> int:
        cm = round(100.0 * self._wall_distance(self.truth_pose.theta))
        return 255 if cm > self.params.us_max_cm else max(0, cm)

    def compass_deg(self) -> float:
        return math.degrees(self.truth_pose.theta) % 360.0

    def render_jpeg(self, path: Path) -> None:
        """A small JPEG whose pixels encode the pose (distinct photos for distinct poses)."""
        w, h = self.params.photo_px
        q = self.truth_pose
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
        phase = q.theta * 4.0 + q.x * 7.0 + q.y * 11.0
        img = 127 + 100 * np.sin(xx / 9.0 + phase) * np.cos(yy / 7.0 - phase)
        img = np.dstack([img, np.roll(img, 13, axis=1), np.roll(img, 29, axis=0)])
        img = np.ascontiguousarray(img.astype(np.uint8))
        cv2.putText(
            img, f"{self.photos}", (5, h - 10), cv2.FONT_HERSHEY_SIMPLEX, 1.0, (255, 255, 255), 2
        )
        ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 90])
        if not ok:
            raise RuntimeError("JPEG encoding failed")
        Path(path).write_bytes(buf.tobytes())
        self.photos += 1
