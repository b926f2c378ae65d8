"""The simulated world: a differential-drive robot in a textured scene.

Physics at the wheel level, so the simulator backend and the NXT brick emulator drive the
same model: wheel speeds are commanded, the world integrates the motion with wheel slip
(mostly on turns), heading drift, collisions of the circular footprint with any geometry
between floor + clearance and the robot's height, and wheels that stop turning when the
robot is pushed against an obstacle (stall). Sensors read the scene: a compass with noise,
an ultrasonic cone (max 2.55 m, 255 = no echo), front and rear bumpers, and a camera
mounted off the rotation axis.

The true pose is available for logging and evaluation only (``truth_pose``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scenebot.config import SimConfig
from scenebot.geometry import Intrinsics, look_rotation
from scenebot.jpeg import write_jpeg
from scenebot.robot.base import ULTRASONIC_NO_ECHO_CM, Pose2D, RobotError
from scenebot.scene.mesh import SceneMesh
from scenebot.sim.obstacles import ObstacleMap
from scenebot.sim.renderer import Renderer


class StartPoseError(RobotError):
    """The start pose is inside or touching an obstacle."""


@dataclass(frozen=True)
class WorldParams:
    """Drive-train constants a motor controller (or the NXT emulator) needs."""

    wheel_radius_m: float
    wheel_base_m: float
    max_wheel_speed_deg_s: float


class SimWorld:
    """The simulated robot and its scene.

    Args:
        scene: the world geometry.
        cfg: simulator settings.
        start: true start pose (world frame).
        seed: seed of all noise (slip, sensors, image noise; the config's ``seed``).
        renderer: an existing renderer of ``scene`` to share (optional).
    """

    def __init__(
        self,
        scene: SceneMesh,
        cfg: SimConfig,
        start: Pose2D,
        seed: int,
        renderer: Renderer | None = None,
    ):
        self.scene = scene
        self.cfg = cfg
        self.rng = np.random.default_rng(seed)
        body, sens = cfg.body, cfg.sensors
        cam = cfg.camera
        self.renderer = renderer or Renderer(
            scene, noise_sigma=cam.noise_sigma, antialias=cam.antialias
        )
        fz = scene.floor_z
        self.collision_map = ObstacleMap.build(scene, fz + body.clearance_m, fz + body.height_m)
        self.bumper_map = ObstacleMap.build(
            scene, fz + sens.bumper_z_min_m, fz + sens.bumper_z_max_m
        )
        clearance = self.collision_map.clearance_at((start.x, start.y))
        if clearance < body.radius_m:
            raise StartPoseError(
                f"start pose ({start.x:.2f}, {start.y:.2f}) m is inside or touching an obstacle "
                f"in scene {scene.name!r} (clearance {clearance:.2f} m < robot radius "
                f"{body.radius_m:.2f} m): set world.start in config.yaml to a free spot"
            )
        self.params = WorldParams(
            body.wheel_radius_m, body.wheel_base_m, body.max_wheel_speed_deg_s
        )
        self.intrinsics = Intrinsics.from_hfov(cam.width, cam.height, cam.hfov_deg)
        self.t = 0.0
        self._pose = np.array([start.x, start.y, start.theta], np.float64)
        self._cmd = (0.0, 0.0)
        self._tacho = np.zeros(2)
        self._slip_drive = 0.0
        self._slip_turn = 0.0
        self._drift = 0.0
        self.blocked = False
        self.max_penetration_m = 0.0

    # ------------------------------------------------------------------ actuation
    def set_wheel_speeds(self, left_deg_s: float, right_deg_s: float) -> None:
        """Command wheel speeds (deg/s); new slip factors are drawn for each new command."""
        limit = self.params.max_wheel_speed_deg_s
        cmd = (
            float(np.clip(left_deg_s, -limit, limit)),
            float(np.clip(right_deg_s, -limit, limit)),
        )
        if cmd != self._cmd and cmd != (0.0, 0.0):
            s = self.cfg.slip
            self._slip_drive = float(np.clip(self.rng.normal(s.drive, s.drive_noise), 0, 0.5))
            self._slip_turn = float(np.clip(self.rng.normal(s.turn, s.turn_noise), 0, 0.5))
            self._drift = math.radians(self.rng.normal(0.0, s.heading_drift_deg_per_m))
        self._cmd = cmd

    def step(self, dt: float) -> None:
        """Advance the physics by ``dt`` seconds (sub-stepped at ``cfg.dt_s``)."""
        n = max(1, math.ceil(dt / self.cfg.dt_s - 1e-9))
        h = dt / n
        for _ in range(n):
            self._substep(h)

    def _substep(self, h: float) -> None:
        wl, wr = self._cmd
        self.t += h
        if wl == 0.0 and wr == 0.0:
            self.blocked = False
            return
        r, b = self.params.wheel_radius_m, self.params.wheel_base_m
        vl, vr = math.radians(wl) * r, math.radians(wr) * r
        v = 0.5 * (vl + vr) * (1.0 - self._slip_drive)
        w = (vr - vl) / b * (1.0 - self._slip_turn) + abs(v) * self._drift
        x, y, th = self._pose
        mid = th + 0.5 * w * h
        nx, ny = x + v * h * math.cos(mid), y + v * h * math.sin(mid)
        radius = self.cfg.body.radius_m
        c_old = self.collision_map.clearance_at((x, y))
        c_new = self.collision_map.clearance_at((nx, ny))
        self.blocked = c_new < radius and c_new < c_old - 1e-9 and abs(v) > 0
        if self.blocked:
            nx, ny = x, y  # pushed against an obstacle: the wheels stall
        else:
            self._tacho += (wl * h, wr * h)
            self.max_penetration_m = max(self.max_penetration_m, radius - c_new)
        self._pose = np.array([nx, ny, (th + w * h) % (2 * math.pi)])

    @property
    def tacho_deg(self) -> tuple[float, float]:
        """Cumulative (left, right) wheel encoder angles in degrees."""
        return float(self._tacho[0]), float(self._tacho[1])

    # -------------------------------------------------------------------- sensors
    @property
    def truth_pose(self) -> Pose2D:
        """The true pose (evaluation and logging only)."""
        return Pose2D(float(self._pose[0]), float(self._pose[1]), float(self._pose[2]))

    def bumpers(self) -> tuple[bool, bool]:
        """(front, rear) bumper switches."""
        x, y, th = self._pose
        if self.bumper_map.clearance_at((x, y)) > self.cfg.body.radius_m + 0.004:
            return False, False
        ox, oy = self.bumper_map.nearest_obstacle((x, y))
        phi = math.atan2(oy - y, ox - x) - th
        phi = math.atan2(math.sin(phi), math.cos(phi))
        half = math.radians(self.cfg.sensors.bumper_arc_deg) / 2
        return abs(phi) <= half, abs(math.pi - abs(phi)) <= half

    def compass_deg(self) -> float:
        """Compass heading (deg, CCW from magnetic north) with noise."""
        s = self.cfg.sensors
        deg = math.degrees(self._pose[2]) - s.compass_offset_deg
        return float((deg + self.rng.normal(0.0, s.compass_noise_deg)) % 360.0)

    def ultrasonic_cm(self) -> int:
        """Ultrasonic range (whole cm) over the sensor's cone; 255 = no echo."""
        s = self.cfg.sensors
        x, y, th = self._pose
        fwd = self.cfg.body.radius_m - 0.02
        origin = np.array(
            [
                x + fwd * math.cos(th),
                y + fwd * math.sin(th),
                self.scene.floor_z + s.ultrasonic_height_m,
            ]
        )
        half = math.radians(s.ultrasonic_cone_deg) / 2
        az, el = np.meshgrid(np.linspace(-half, half, 9), np.linspace(-half / 2, half / 2, 3))
        az, el = az.ravel() + th, el.ravel()
        dirs = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], 1)
        hit = self.renderer.cast(np.broadcast_to(origin, dirs.shape), dirs)
        ok = hit["prim"] >= 0
        if not np.any(ok):
            return ULTRASONIC_NO_ECHO_CM
        normals = self.renderer._normals[hit["prim"][ok]]
        cos_inc = np.abs(np.sum(normals * dirs[ok], axis=1))
        valid = cos_inc >= math.cos(math.radians(s.ultrasonic_max_incidence_deg))
        t = hit["t"][ok][valid]
        if len(t) == 0 or t.min() > s.ultrasonic_max_m:
            return ULTRASONIC_NO_ECHO_CM
        cm = t.min() * 100.0 + self.rng.normal(0.0, s.ultrasonic_noise_cm)
        return int(np.clip(round(cm), 3, 254))

    # --------------------------------------------------------------------- camera
    def camera_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """True (R_cam_from_world (3, 3), centre (3,)) of the robot's camera."""
        cam = self.cfg.camera
        x, y, th = self._pose
        c, s = math.cos(th), math.sin(th)
        center = np.array(
            [
                x + cam.forward_offset_m * c - cam.lateral_offset_m * s,
                y + cam.forward_offset_m * s + cam.lateral_offset_m * c,
                self.scene.floor_z + cam.height_m,
            ]
        )
        return look_rotation(th, math.radians(cam.pitch_deg)), center

    def render(self) -> np.ndarray:
        """The photo the camera would take now: (H, W, 3) uint8."""
        R, c = self.camera_pose()
        return self.renderer.render(self.intrinsics, R, c, self.rng)

    def render_jpeg(self, path: Path) -> Path:
        """Take a photo and write it as a JPEG with EXIF focal length."""
        cam = self.cfg.camera
        return write_jpeg(
            Path(path), self.render(), self.intrinsics.fx, cam.sensor_width_mm, cam.jpeg_quality
        )

    def truth_record(self) -> dict:
        """The true robot and camera pose, for the capture log's ``truth`` field."""
        R, c = self.camera_pose()
        p = self.truth_pose
        return {
            "robot": {"x": p.x, "y": p.y, "theta": p.theta},
            "center": c.tolist(),
            "R_cam_from_world": R.tolist(),
        }
