"""Round 0: random exploration (paper section IV.A), written against the robot boundary.

The robot takes circles of photos, turning in place by ``circle_step_deg`` between photos and
recording the compass and ultrasonic range with each. When a circle completes it turns to the
compass heading at which the ultrasonic range was longest ("no echo" counts as longest) and
drives a random distance. It does not avoid obstacles: on a bump or a stall it backs up,
turns a random angle in a random direction, and continues straight for the rest of the leg.
It stops after the configured number of photos.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scenebot.capturelog import CaptureLog, write_faults
from scenebot.config import ExplorationConfig
from scenebot.robot.base import Camera, MotionResult, MotionStatus, Robot, SensorReading


@dataclass
class ExplorationResult:
    photos: int
    bumps: int
    stalls: int
    circles: int


class PhotoTaker:
    """Takes a photo, reads the sensors, and logs both (one ``photo`` record)."""

    def __init__(
        self,
        robot: Robot,
        camera: Camera,
        log: CaptureLog,
        capture_dir: Path,
        prefix: str,
        on_photo: Callable[[int], None] | None = None,
    ):
        self.robot, self.camera, self.log = robot, camera, log
        self.capture_dir = Path(capture_dir)
        self.prefix = prefix
        self.count = 0
        self.on_photo = on_photo

    def take(self, extra: dict | None = None) -> SensorReading:
        reading = self.robot.sense()
        name = f"images/{self.prefix}_{self.count:04d}.jpg"
        self.camera.capture(self.capture_dir / name)
        record = {"type": "photo", "index": self.count, "image": name, **reading.as_record()}
        if extra:
            record.update(extra)
        truth = getattr(self.robot, "truth_record", None)
        if truth is not None:
            record["truth"] = truth()
        write_faults(self.log, self.robot)
        self.log.write(record)
        self.count += 1
        if self.on_photo:
            self.on_photo(self.count)
        return reading


def log_event(log: CaptureLog, robot: Robot, event: str, **fields) -> None:
    """Write an ``event`` record with the odometry (and the truth in the simulator)."""
    sensors = robot.sense()
    record = {
        "type": "event",
        "t": robot.now,
        "event": event,
        "odometry": sensors.odometry.as_dict(),
        "bump_front": sensors.bump_front,
        "bump_rear": sensors.bump_rear,
        **fields,
    }
    truth = getattr(robot, "truth_record", None)
    if truth is not None:
        record["truth"] = truth()["robot"]
    write_faults(log, robot)
    log.write(record)


def _motion_fields(res: MotionResult) -> dict:
    return {
        "status": str(res.status),
        "distance_m": res.distance_m,
        "angle_rad": res.angle_rad,
        "bumper": res.bumper,
    }


def best_heading(readings: list[tuple[float, int]]) -> float:
    """Compass heading (deg) with the longest ultrasonic range; 255 (no echo) is longest.

    Ties (e.g. several "no echo" readings) go to the middle of the longest run of equal
    maxima, which points down the open direction rather than at its edge.
    """
    ranges = np.array([r for _, r in readings], dtype=float)
    best = ranges.max()
    idx = np.nonzero(ranges == best)[0]
    runs: list[list[int]] = [[int(idx[0])]]
    for i in idx[1:]:
        if i == runs[-1][-1] + 1:
            runs[-1].append(int(i))
        else:
            runs.append([int(i)])
    run = max(runs, key=len)
    return readings[run[len(run) // 2]][0]


def random_exploration(
    robot: Robot,
    photos: PhotoTaker,
    log: CaptureLog,
    cfg: ExplorationConfig,
    rng: np.random.Generator,
) -> ExplorationResult:
    """Run random exploration until ``cfg.photos`` photos are taken.

    Args:
        robot: the robot.
        photos: takes and logs photos.
        log: the capture log for events.
        cfg: exploration settings.
        rng: randomness of distances and escape turns.
    """
    bumps = stalls = circles = 0
    step = math.radians(cfg.circle_step_deg)
    per_circle = max(1, round(360.0 / cfg.circle_step_deg))
    while photos.count < cfg.photos:
        readings: list[tuple[float, int]] = []
        for k in range(per_circle):
            if photos.count >= cfg.photos:
                break
            s = photos.take({"circle": circles, "circle_index": k})
            readings.append((s.compass_deg, s.ultrasonic_cm))
            if k < per_circle - 1 and photos.count < cfg.photos:
                robot.turn(step)
        circles += 1
        log_event(log, robot, "circle_done", circle=circles - 1, photos=len(readings))
        if photos.count >= cfg.photos:
            break
        heading = best_heading(readings)
        res = robot.turn_to_heading(heading)
        log_event(log, robot, "turn", target_compass_deg=heading, **_motion_fields(res))
        remaining = float(rng.uniform(cfg.drive_min_m, cfg.drive_max_m))
        log_event(log, robot, "leg", distance_m=remaining)
        escapes = 0
        while remaining > 0.02 and escapes < cfg.max_escapes:
            res = robot.drive(remaining)
            remaining -= max(res.distance_m, 0.0)
            log_event(log, robot, "drive", **_motion_fields(res))
            if not res.interrupted:
                break
            if res.status is MotionStatus.BUMPED:
                bumps += 1
                log_event(log, robot, "bump", bumper=res.bumper)
            elif res.status is MotionStatus.STALLED:
                stalls += 1
                log_event(log, robot, "stall")
            else:
                log_event(log, robot, "error", status=str(res.status))
                break
            escapes += 1
            back = robot.drive(-cfg.backup_m)
            log_event(log, robot, "backup", **_motion_fields(back))
            angle = math.radians(rng.uniform(cfg.escape_turn_min_deg, cfg.escape_turn_max_deg))
            angle *= 1 if rng.random() < 0.5 else -1
            res = robot.turn(angle)
            log_event(log, robot, "escape_turn", **_motion_fields(res))
    return ExplorationResult(photos.count, bumps, stalls, circles)
