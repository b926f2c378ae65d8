"""A small synthetic capture for tests and benchmarks of the sfm stage (no simulator needed).

A box-shaped room (textured walls, floor and ceiling) is ray-cast from a robot that takes
circles of photos at a few spots, like round-0 random exploration. The robot logs noisy
odometry (slip on turns) and a noisy compass in the capture-log format of
:mod:`scenebot.capturelog`, plus the true camera poses under ``truth`` (evaluation only).
Photos are JPEGs with EXIF focal length and focal-plane resolution, like the simulator's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from PIL import Image

from scenebot.capturelog import CaptureLog
from scenebot.jpeg import write_jpeg


@dataclass
class SyntheticRoom:
    """Room and camera parameters.

    Attributes:
        size_m: room extent (x, y, z) in metres; the room spans ``[0, size]`` on each axis.
        width, height: image size (px).
        focal_px: focal length (px); principal point at the image centre.
        camera_height_m: height of the optical centre above the floor (m).
        camera_offset_m: camera centre in the robot frame (forward, left) (m): off the
            rotation axis, so photos of a turn in place have a baseline.
        compass_offset_deg: compass reading when the robot faces the world +x axis.
        seed: random seed (textures, noise).
    """

    size_m: tuple[float, float, float] = (6.0, 5.0, 2.6)
    width: int = 320
    height: int = 240
    focal_px: float = 260.0
    camera_height_m: float = 0.3
    camera_offset_m: tuple[float, float] = (0.10, 0.0)
    compass_offset_deg: float = 25.0
    seed: int = 0

    def __post_init__(self) -> None:
        rng = np.random.default_rng(self.seed)
        self.textures = [_texture(rng, 1024) for _ in range(6)]

    def cam_from_world(self, x: float, y: float, theta: float) -> tuple[np.ndarray, np.ndarray]:
        """Camera pose for the robot at ``(x, y, theta)`` (m, rad), world frame.

        Returns:
            ``R`` (3, 3) cam_from_world rotation and camera centre ``c`` (3,) in metres.
        """
        fwd = np.array([math.cos(theta), math.sin(theta), 0.0])
        left = np.array([-math.sin(theta), math.cos(theta), 0.0])
        c = np.array([x, y, self.camera_height_m]) + self.camera_offset_m[0] * fwd
        c = c + self.camera_offset_m[1] * left
        R = np.stack([-left, [0.0, 0.0, -1.0], fwd])  # rows: camera x (right), y (down), z
        return R, c

    def render(self, R: np.ndarray, c: np.ndarray) -> np.ndarray:
        """Ray-cast the room: (height, width, 3) uint8 RGB image seen by camera (R, c)."""
        h, w = self.height, self.width
        u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
        rays_cam = np.stack(
            [(u - w / 2) / self.focal_px, (v - h / 2) / self.focal_px, np.ones_like(u)], -1
        )
        d = rays_cam @ R  # world directions, (h, w, 3)
        size = np.asarray(self.size_m)
        with np.errstate(divide="ignore", invalid="ignore"):
            bound = np.where(d > 0, size, 0.0)
            t_axis = np.where(np.abs(d) > 1e-12, (bound - c) / d, np.inf)
        axis = np.argmin(t_axis, axis=-1)
        t = np.take_along_axis(t_axis, axis[..., None], -1)[..., 0]
        p = c + d * t[..., None]
        positive = np.take_along_axis(d, axis[..., None], -1)[..., 0] > 0
        face = axis * 2 + positive.astype(int)
        out = np.zeros((h, w, 3), np.float32)
        for f in range(6):
            mask = face == f
            if not mask.any():
                continue
            ax = f // 2
            a, b = [k for k in range(3) if k != ax]
            tex = self.textures[f]
            th, tw = tex.shape[:2]
            map_x = (p[..., a] / size[a] * (tw - 1)).astype(np.float32)
            map_y = (p[..., b] / size[b] * (th - 1)).astype(np.float32)
            sampled = cv2.remap(tex, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
            shade = 0.75 + 0.25 * ((f * 37) % 5) / 4.0  # faces differ in brightness
            out[mask] = sampled[mask].astype(np.float32) * shade
        return np.clip(out, 0, 255).astype(np.uint8)


def _texture(rng: np.random.Generator, n: int) -> np.ndarray:
    """A feature-rich texture: multi-scale noise plus random rectangles and discs, (n, n, 3)."""
    img = np.zeros((n, n, 3), np.float32)
    for scale, amp in [(4, 60.0), (16, 50.0), (64, 40.0), (256, 30.0)]:
        small = rng.random((scale, scale, 3)).astype(np.float32)
        img += cv2.resize(small, (n, n), interpolation=cv2.INTER_CUBIC) * amp
    img = img - img.min()
    img = img / img.max() * 200.0
    for _ in range(300):
        color = rng.integers(0, 256, 3).tolist()
        x0, y0 = rng.integers(0, n, 2)
        r = int(rng.integers(4, 40))
        if rng.random() < 0.5:
            cv2.circle(img, (int(x0), int(y0)), r, color, -1)
        else:
            cv2.rectangle(img, (int(x0), int(y0)), (int(x0) + r, int(y0) + r // 2), color, -1)
    return np.clip(img, 0, 255).astype(np.uint8)


def write_jpeg_with_exif(
    path: Path, rgb: np.ndarray, focal_px: float | None, quality: int = 92
) -> None:
    """Write ``rgb`` (H, W, 3) uint8 as a JPEG with EXIF like the simulator's camera.

    The EXIF holds Make/Model, FocalLength (mm), FocalLengthIn35mmFilm and the focal-plane
    resolution (px per cm) of a 4.8 mm wide sensor, so ``focal_px`` can be recovered
    exactly. ``focal_px=None`` writes no focal tags (for the "no EXIF focal" case).
    """
    if focal_px is None:
        exif = Image.Exif()
        exif[0x010F] = "scenebot"
        exif[0x0110] = "synthetic room camera"
        Image.fromarray(rgb).save(path, "JPEG", quality=quality, exif=exif.tobytes())
        return
    write_jpeg(
        Path(path), rgb, focal_px, sensor_width_mm=4.8, quality=quality,
        model="synthetic room camera",
    )  # fmt: skip


def circle_spots(room: SyntheticRoom, n_spots: int, rng: np.random.Generator) -> np.ndarray:
    """``n_spots`` robot positions (m), spread over the room's interior, (n_spots, 2)."""
    sx, sy = room.size_m[0], room.size_m[1]
    cx, cy = sx / 2, sy / 2
    rad = 0.28 * min(sx, sy)
    angles = np.linspace(0.0, 2 * math.pi, n_spots, endpoint=False) + rng.uniform(0, 0.5)
    pts = np.stack([cx + rad * np.cos(angles), cy + rad * np.sin(angles)], -1)
    return pts + rng.normal(0, 0.1, pts.shape)


@dataclass
class _Robot:
    """The robot's true pose and its odometry (x, y, theta; m, rad), which integrates encoder
    distances with a relative error ``odometry_noise`` and turns with a relative slip
    ``turn_slip`` (noise drawn from ``rng``)."""

    true: np.ndarray
    odo: np.ndarray
    rng: np.random.Generator
    turn_slip: float
    odometry_noise: float

    def turn(self, angle: float) -> None:
        """Turn in place by ``angle`` (rad); odometry under-reads it by the slip."""
        slip = self.turn_slip * self.rng.uniform(0.5, 1.5)
        self.true[2] = (self.true[2] + angle) % (2 * math.pi)
        self.odo[2] = (self.odo[2] + angle * (1.0 - slip)) % (2 * math.pi)

    def drive(self, dist: float) -> None:
        """Drive ``dist`` (m) straight ahead; odometry reads it with noise."""
        true, odo = self.true, self.odo
        true[:2] += dist * np.array([math.cos(true[2]), math.sin(true[2])])
        d_odo = dist * (1.0 + self.rng.normal(0, self.odometry_noise))
        odo[:2] += d_odo * np.array([math.cos(odo[2]), math.sin(odo[2])])

    def go_to(self, spot: np.ndarray) -> None:
        """Turn towards ``spot`` (m) and drive there."""
        delta = spot - self.true[:2]
        heading = math.atan2(delta[1], delta[0])
        self.turn((heading - self.true[2] + math.pi) % (2 * math.pi) - math.pi)
        self.drive(float(np.linalg.norm(delta)))


@dataclass
class _Localizer:
    """The robot's visual localization of an adaptive round, faked from the truth: the true
    robot pose in the map frame (round 0's first robot position as origin, x along compass
    heading 0) plus Gaussian noise ``noise_m`` (m, per axis) and a constant ``bias_m``."""

    origin: np.ndarray
    compass_offset_deg: float
    noise_m: float
    bias_m: np.ndarray
    rng: np.random.Generator

    def fix(self, true: np.ndarray) -> dict:
        a = math.radians(self.compass_offset_deg)
        c, s = math.cos(a), math.sin(a)
        d = true[:2] - self.origin
        xy = np.array([c * d[0] - s * d[1], s * d[0] + c * d[1]])
        xy = xy + self.bias_m + self.rng.normal(0.0, self.noise_m, 2)
        theta = (true[2] + a) % (2 * math.pi)
        return {"x": float(xy[0]), "y": float(xy[1]), "theta": float(theta)}


def _session_record(room: SyntheticRoom, round_index: int) -> dict:
    """The capture log's first record: robot, scene, round and camera."""
    return {
        "type": "session",
        "robot": "synthetic",
        "scene": "synthetic_room",
        "round": round_index,
        "camera": {
            "width": room.width,
            "height": room.height,
            "focal_px": room.focal_px,
            "model": "PINHOLE",
        },
    }


def _take_photo(
    out_dir: Path,
    room: SyntheticRoom,
    robot: _Robot,
    round_index: int,
    idx: int,
    t: float,
    compass_noise_deg: float,
    exif_focal: bool,
    localizer: _Localizer | None = None,
) -> dict:
    """Render and write photo ``idx`` at the robot's true pose; its log record (noisy
    compass, odometry, truth; with ``localizer`` a visual fix of the photo)."""
    true, odo = robot.true, robot.odo
    R, c = room.cam_from_world(*true)
    name = f"images/r{round_index:03d}_{idx:04d}.jpg"
    write_jpeg_with_exif(out_dir / name, room.render(R, c), room.focal_px if exif_focal else None)
    compass = (
        math.degrees(true[2]) + room.compass_offset_deg + robot.rng.normal(0, compass_noise_deg)
    ) % 360.0
    fix = {}
    if localizer is not None:
        fix = {"localization": localizer.fix(true), "localization_source": "this photo"}
    return {
        "type": "photo",
        "t": t,
        "index": idx,
        "image": name,
        "odometry": {"x": odo[0], "y": odo[1], "theta": odo[2]},
        "compass_deg": compass,
        "ultrasonic_cm": 255,
        "bump_front": False,
        "bump_rear": False,
        **fix,
        "truth": {
            "robot": {"x": true[0], "y": true[1], "theta": true[2]},
            "center": c.tolist(),
            "R_cam_from_world": R.reshape(-1).tolist(),
        },
    }


def make_capture(
    out_dir: Path,
    room: SyntheticRoom | None = None,
    *,
    n_spots: int = 3,
    photos_per_circle: int = 12,
    round_index: int = 0,
    start_spot: int = 0,
    odometry_noise: float = 0.01,
    turn_slip: float = 0.03,
    compass_noise_deg: float = 1.0,
    seed: int = 1,
    exif_focal: bool = True,
    map_origin: tuple[float, float] | None = None,
    localization_noise_m: float = 0.005,
    localization_bias_m: tuple[float, float] = (0.0, 0.0),
) -> list[dict]:
    """Write a synthetic round capture: ``out_dir/images/*.jpg`` and ``out_dir/log.jsonl``.

    The robot starts at the first spot, takes ``photos_per_circle`` photos on a full turn in
    place, then turns towards and drives to the next spot, and so on. Odometry integrates
    encoder distances with a relative error ``odometry_noise`` and turn angles with a relative
    slip ``turn_slip``; the compass adds Gaussian noise (deg).

    Args:
        out_dir: the capture folder (created).
        room: the room (default: ``SyntheticRoom()``).
        n_spots: number of photo circles.
        photos_per_circle: photos per full turn.
        round_index: round number written in names and records.
        start_spot: index of the first spot on the spot ring (later rounds visit other spots).
        seed: random seed for the noise.
        exif_focal: write EXIF focal tags.
        map_origin: an adaptive round's map frame: the world position (m) of round 0's
            first robot position (its ``truth.robot``); every photo record then holds the
            robot's visual fix of it (``localization``, ``localization_source``: the true
            pose in the map frame, with Gaussian noise ``localization_noise_m`` (m) per axis
            and a constant offset ``localization_bias_m`` (m, map frame)).

    Returns:
        The photo records written (with ``truth``).
    """
    room = room or SyntheticRoom()
    rng = np.random.default_rng(seed)
    out_dir = Path(out_dir)
    (out_dir / "images").mkdir(parents=True, exist_ok=True)
    spots = circle_spots(room, n_spots + start_spot, np.random.default_rng(room.seed + 7))
    spots = spots[start_spot:]
    true = np.array([spots[0][0], spots[0][1], rng.uniform(0, 2 * math.pi)])
    compass0 = (math.degrees(true[2]) + room.compass_offset_deg) % 360.0
    odo = np.array([0.0, 0.0, math.radians(compass0)])
    robot = _Robot(true, odo, rng, turn_slip, odometry_noise)
    localizer = None
    if map_origin is not None:
        localizer = _Localizer(
            np.asarray(map_origin, float),
            room.compass_offset_deg,
            localization_noise_m,
            np.asarray(localization_bias_m, float),
            np.random.default_rng(seed + 1000),
        )
    records: list[dict] = []
    t = 0.0
    idx = 0
    log_path = out_dir / "log.jsonl"
    if log_path.exists():
        log_path.unlink()
    with CaptureLog(log_path) as log:
        log.write(_session_record(room, round_index))
        for k in range(len(spots)):
            for _ in range(photos_per_circle):
                rec = _take_photo(
                    out_dir, room, robot, round_index, idx, t, compass_noise_deg, exif_focal,
                    localizer,
                )  # fmt: skip
                log.write(rec)
                records.append(rec)
                idx += 1
                t += 2.0
                robot.turn(2 * math.pi / photos_per_circle)
            if k + 1 < len(spots):
                robot.go_to(spots[k + 1])
                t += 5.0
        log.write({"type": "end", "t": t, "photos": idx, "reason": "done"})
    return records
