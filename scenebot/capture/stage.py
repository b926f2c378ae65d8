"""The capture stage of round 0: random exploration with the configured robot, photos and
log written into ``results/{scene}/round_000/capture/`` as :mod:`scenebot.capture.session`
describes (the lock, the archive of an earlier attempt, the log, the picture).
"""

from __future__ import annotations

import math
from dataclasses import asdict
from pathlib import Path

import numpy as np
from tqdm import tqdm

from scenebot.capture.session import (
    SESSION_LOG,
    capture_lock,
    finish_capture,
    session_record,
    start_capture,
    stopping_safely,
)
from scenebot.capturelog import CaptureLog, read_log, write_faults
from scenebot.config import Config
from scenebot.robot.factory import make_backend


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
    from scenebot.capture.explore import PhotoTaker, random_exploration

    capture_dir = Path(capture_dir)
    with capture_lock(capture_dir):
        start_capture(capture_dir)
        robot, camera, world = make_backend(cfg, capture_dir)
        session = capture_dir / SESSION_LOG
        rng = np.random.default_rng([cfg.seed, round_index])
        with CaptureLog(session) as clog, robot:
            clog.write(
                session_record(cfg, robot, world, round_index, {"world", "sim", "exploration"})
            )
            bar = tqdm(total=cfg.exploration.photos, desc=f"round {round_index} photos",
                       unit="photo", disable=not progress)  # fmt: skip
            taker = PhotoTaker(
                robot, camera, clog, capture_dir, f"r{round_index:03d}",
                on_photo=lambda n: bar.update(1),
            )  # fmt: skip
            with stopping_safely(clog, robot, capture_dir, world, bar):
                result = random_exploration(robot, taker, clog, cfg.exploration, rng)
            summary = asdict(result)
            if world is not None:
                summary["max_penetration_m"] = world.max_penetration_m
            write_faults(clog, robot)  # the faults recovered after the last photo or event
            clog.write({"type": "end", "t": robot.now, "reason": "photo budget reached", **summary})
        finish_capture(capture_dir, lambda out, png: plot_trajectory(out, png, world))
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
