"""The capture stage: drive the robot, take photos, log everything.

Writes into ``results/{scene}/round_{r}/capture/``:

* ``images/*.jpg`` — the photos (made read-only; never deleted: a re-run first moves an
  earlier attempt, photos and its log, to ``superseded/<time>/``);
* ``session.jsonl`` — the live log, one record per photo and event, flushed as it goes, so
  a crash loses nothing;
* ``log.jsonl`` — the finished log (a hard link to ``session.jsonl``), the stage's output;
* ``trajectory.png`` — top-down map with the trajectory, photo positions and bump events.
"""

from __future__ import annotations

import datetime as dt
import logging
import math
import os
import shutil
import stat
from dataclasses import asdict
from pathlib import Path

import numpy as np
from tqdm import tqdm

from scenebot.capturelog import CaptureLog, read_log
from scenebot.config import Config
from scenebot.robot.base import Pose2D

log = logging.getLogger("scenebot.capture")


def archive_previous(capture_dir: Path) -> Path | None:
    """Move an earlier attempt's photos and logs to ``superseded/<time>/`` (never delete)."""
    capture_dir = Path(capture_dir)
    images = capture_dir / "images"
    movable = [p for p in (images, capture_dir / "session.jsonl", capture_dir / "log.jsonl")]
    has_photos = images.is_dir() and any(images.iterdir())
    if not has_photos and not (capture_dir / "session.jsonl").exists():
        return None
    stamp = dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    dest = capture_dir / "superseded" / stamp
    k = 1
    while dest.exists():
        dest = capture_dir / "superseded" / f"{stamp}-{k}"
        k += 1
    dest.mkdir(parents=True)
    for p in movable:
        if p.exists():
            shutil.move(str(p), dest / p.name)
    log.warning("an earlier capture in %s was moved to %s (nothing deleted)", capture_dir, dest)
    return dest


def _start_pose(cfg: Config, scene, collision_map) -> Pose2D:
    if cfg.world.start is not None:
        s = cfg.world.start
        return Pose2D(s.x, s.y, math.radians(s.theta_deg))
    if scene.start is not None:
        return scene.start
    r, c = np.unravel_index(np.argmax(collision_map.clearance), collision_map.clearance.shape)
    xy = collision_map.origin + np.array([c, r]) * collision_map.res
    return Pose2D(float(xy[0]), float(xy[1]), 0.0)


def session_record(cfg: Config, robot, world, round_index: int, sections: set, **extra) -> dict:
    """The first record of a capture log (see :mod:`scenebot.capturelog`): robot, scene,
    round, start time, camera, the config ``sections`` the capture used, and ``extra``."""
    cam = cfg.sim.camera
    return {
        "type": "session",
        "t": robot.now,
        "robot": cfg.robot,
        "scene": cfg.scene,
        "round": round_index,
        "started": dt.datetime.now().isoformat(timespec="seconds"),
        **extra,
        "camera": {
            "model": "PINHOLE",
            "width": cam.width,
            "height": cam.height,
            # the simulator's exact focal; a real camera's EXIF is the authority
            "focal_px": world.intrinsics.fx if world is not None else None,
        },
        "config": cfg.model_dump(mode="json", include=sections),
    }


def make_sim_backend(cfg: Config, start: Pose2D | None = None):
    """(robot, camera, world) of the simulator for ``cfg``.

    ``start``: the true start pose (world frame) when the world continues from an earlier
    round (its ``sim_state.json``); default: the configured or the scene's start pose.
    """
    from scenebot.robot.sim import SimCamera, SimRobot
    from scenebot.scene.loader import load_world_scene
    from scenebot.sim.obstacles import ObstacleMap
    from scenebot.sim.world import SimWorld

    scene = load_world_scene(cfg.world)
    body = cfg.sim.body
    if start is None:
        cmap = None
        if cfg.world.start is None and scene.start is None:
            cmap = ObstacleMap.build(
                scene, scene.floor_z + body.clearance_m, scene.floor_z + body.height_m
            )
        start = _start_pose(cfg, scene, cmap)
    world = SimWorld(scene, cfg.sim, start, seed=cfg.seed)
    return SimRobot(world), SimCamera(world), world


def make_backend(cfg: Config, capture_dir: Path, start: Pose2D | None = None):
    """(robot, camera, world or None) of the configured ``robot`` backend.

    ``sim``: the simulator. ``nxt``: a LEGO NXT on ``nxt.port`` with photos arriving in
    ``nxt.camera.inbox``. ``nxt-emulated``: the same driver talking, through a
    pseudo-terminal, to the brick emulator backed by the simulator; its Wi-Fi card writes to
    ``<capture>/inbox`` so photos move into ``images/`` by rename. ``start``: for the
    simulator backends, the true pose the world continues from (see
    :func:`make_sim_backend`); a real robot is where it is.
    """
    if cfg.robot == "sim":
        return make_sim_backend(cfg, start)
    from scenebot.robot.nxt.backend import make_nxt_backend

    emulated = cfg.robot == "nxt-emulated"
    return make_nxt_backend(
        cfg,
        cfg.nxt,
        emulated=emulated,
        emulator=cfg.nxt_emulator,
        inbox=Path(capture_dir) / "inbox" if emulated else None,
        start=start,
    )


def run_capture(cfg: Config, capture_dir: Path, round_index: int = 0, progress: bool = True):
    """Round-0 capture: random exploration with the configured robot backend.

    Args:
        cfg: the campaign config.
        capture_dir: ``results/{scene}/round_000/capture``.
        round_index: the round (0 for random exploration).
        progress: show a progress bar of photos taken.

    Returns:
        The exploration summary (photos, bumps, stalls, circles) as a dict.
    """
    from scenebot.adaptive import write_sim_state
    from scenebot.explore import PhotoTaker, random_exploration

    capture_dir = Path(capture_dir)
    capture_dir.mkdir(parents=True, exist_ok=True)
    archive_previous(capture_dir)
    (capture_dir / "images").mkdir(exist_ok=True)
    robot, camera, world = make_backend(cfg, capture_dir)
    session = capture_dir / "session.jsonl"
    rng = np.random.default_rng([cfg.seed, round_index])
    with CaptureLog(session) as clog, robot:
        clog.write(session_record(cfg, robot, world, round_index, {"world", "sim", "exploration"}))
        bar = tqdm(total=cfg.exploration.photos, desc=f"round {round_index} photos",
                   unit="photo", disable=not progress)  # fmt: skip
        taker = PhotoTaker(
            robot, camera, clog, capture_dir, f"r{round_index:03d}",
            on_photo=lambda n: bar.update(1),
        )  # fmt: skip
        try:
            result = random_exploration(robot, taker, clog, cfg.exploration, rng)
        except BaseException as exc:
            clog.write({"type": "event", "t": robot.now, "event": "error", "error": repr(exc)})
            raise
        finally:
            bar.close()
            robot.stop()
            write_sim_state(capture_dir, world)
        summary = asdict(result)
        if world is not None:
            summary["max_penetration_m"] = world.max_penetration_m
        clog.write({"type": "end", "t": robot.now, "reason": "photo budget reached", **summary})
    for img in (capture_dir / "images").glob("*.jpg"):
        img.chmod(stat.S_IRUSR | stat.S_IRGRP | stat.S_IROTH)
    out = capture_dir / "log.jsonl"
    if out.exists():
        out.unlink()
    os.link(session, out)
    plot_trajectory(out, capture_dir / "trajectory.png", world)
    return summary


def plot_trajectory(log_path: Path, png: Path, world=None) -> Path:
    """Top-down picture of a capture: trajectory, photo poses, bumps and stalls.

    In the simulator the true trajectory is drawn over the true obstacle map (a picture for
    people, not an input to any decision), with the odometry aligned at the start pose.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    records = list(read_log(log_path))
    photos = [r for r in records if r.get("type") == "photo"]
    events = [r for r in records if r.get("type") == "event"]
    fig, ax = plt.subplots(figsize=(8, 7), dpi=110)
    has_truth = bool(photos) and "truth" in photos[0]
    if world is not None:
        m = world.collision_map
        h, w = m.occupied.shape
        ext = [m.origin[0], m.origin[0] + w * m.res, m.origin[1], m.origin[1] + h * m.res]
        ax.imshow(m.occupied, origin="lower", extent=ext, cmap="Greys", alpha=0.5)

    def odo_xy(rec):
        return np.array([rec["odometry"]["x"], rec["odometry"]["y"]])

    seq = [r for r in records if r.get("type") in ("photo", "event") and "odometry" in r]
    odo = np.array([odo_xy(r) for r in seq]) if seq else np.zeros((0, 2))
    if has_truth:
        t0 = photos[0]["truth"]["robot"]
        o0 = photos[0]["odometry"]
        dth = t0["theta"] - o0["theta"]
        Rz = np.array([[math.cos(dth), -math.sin(dth)], [math.sin(dth), math.cos(dth)]])
        odo_w = (odo - odo_xy(photos[0])) @ Rz.T + [t0["x"], t0["y"]]
        truth = np.array(
            [[r["truth"]["x"], r["truth"]["y"]] if "x" in r["truth"] else
             [r["truth"]["robot"]["x"], r["truth"]["robot"]["y"]] for r in seq if "truth" in r]
        )  # fmt: skip
        ax.plot(truth[:, 0], truth[:, 1], "-", color="tab:blue", lw=1.5, label="true path")
        ax.plot(odo_w[:, 0], odo_w[:, 1], "--", color="tab:orange", lw=1, label="odometry")
        for p in photos:
            c = np.array(p["truth"]["center"])
            fwd = np.array(p["truth"]["R_cam_from_world"])[2]
            ax.arrow(c[0], c[1], 0.15 * fwd[0], 0.15 * fwd[1], width=0.004, color="tab:green",
                     head_width=0.03, alpha=0.7, length_includes_head=True)  # fmt: skip
        pos = {id(r): r["truth"] for r in seq if "truth" in r}
        frame = "world frame (simulator truth)"
    else:
        ax.plot(odo[:, 0], odo[:, 1], "-", color="tab:orange", lw=1.5, label="odometry")
        for p in photos:
            o = p["odometry"]
            ax.arrow(o["x"], o["y"], 0.15 * math.cos(o["theta"]), 0.15 * math.sin(o["theta"]),
                     width=0.004, color="tab:green", head_width=0.03, alpha=0.7)  # fmt: skip
        pos = {id(r): r["odometry"] for r in seq}
        frame = "odometry frame"

    def xy(r):
        p = pos.get(id(r))
        if p is None:
            return None
        p = p.get("robot", p)
        return p["x"], p["y"]

    for kind, marker, color in (("bump", "x", "red"), ("stall", "s", "purple")):
        pts = [xy(e) for e in events if e["event"] == kind]
        pts = [p for p in pts if p is not None]
        if pts:
            a = np.array(pts)
            ax.scatter(a[:, 0], a[:, 1], marker=marker, color=color, s=60, zorder=5,
                       label=f"{kind} ({len(pts)})")  # fmt: skip
    ax.plot([], [], color="tab:green", lw=3, label=f"photos ({len(photos)})")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"{Path(log_path).parent.parent.name}: capture, {frame}")
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(png)
    plt.close(fig)
    return png
