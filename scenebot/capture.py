"""The capture stage: drive the robot, take photos, log everything.

Writes into ``results/{scene}/round_{r}/capture/``:

* ``images/*.jpg`` — the photos (made read-only; each stored atomically, verified to
  decode before it is logged, and never written over an existing file);
* ``session.jsonl`` — the live log, one record per photo and event, fsynced as it goes, so
  a crash loses nothing;
* ``log.jsonl`` — the finished log (a hard link to ``session.jsonl``), the stage's output;
* ``trajectory.png`` — top-down map with the trajectory, photo positions and bump events
  (a hard link to ``session.png``: Snakemake deletes a rule's outputs before it re-runs it,
  the ``session.*`` names keep the earlier attempt's log and picture for the archive);
* ``capture.lock`` — the capture lock (:func:`capture_lock`): while a capture runs, it
  names the process; a second capture of the same round is refused.

Nothing is ever deleted or overwritten: a re-take (a killed, failed or forced capture run
again) first moves every file the earlier attempt wrote (photos, ``nav/``, logs, pictures,
anything else) to ``superseded/<time>/`` with the same relative paths, so the archived log's
image paths (relative to the capture folder) resolve to the archived photos.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import errno
import fcntl
import json
import logging
import math
import os
import shlex
import socket
import stat
import sys
from collections.abc import Callable, Iterator
from dataclasses import asdict
from pathlib import Path

import numpy as np
from tqdm import tqdm

from scenebot.capturelog import CaptureLog, LogWriteError, read_log
from scenebot.config import Config
from scenebot.jpeg import PhotoWriteError, publish, space_left
from scenebot.robot.base import Pose2D

log = logging.getLogger("scenebot.capture")

SESSION_LOG = "session.jsonl"
SESSION_PICTURE = "session.png"
LOCK_NAME = "capture.lock"
SUPERSEDED = "superseded"
NOT_ARCHIVED = (SUPERSEDED, LOCK_NAME)
"""What a re-take leaves in place: the archive itself and the lock of the capture now."""


class CaptureLockedError(RuntimeError):
    """Another capture holds this round's capture folder (the message names it)."""


class CaptureWriteError(RuntimeError):
    """A file of the capture other than a photo or a log record could not be written."""


def archive_previous(capture_dir: Path) -> Path | None:
    """Move everything an earlier attempt wrote to ``superseded/<time>/`` (never delete).

    Every entry of ``capture_dir`` but ``superseded/`` and the lock moves, by rename, to
    the same relative path under ``superseded/<time>/``: photos, ``nav/``, ``inbox/``
    leftovers, logs (``log.jsonl`` stays a hard link of ``session.jsonl``), pictures,
    ``sim_state.json`` and any other file. Image paths in the log are relative to the
    capture folder, so the archived log points at the archived photos.

    Returns:
        The archive folder, or None when there was no file to move.
    """
    capture_dir = Path(capture_dir)
    if not capture_dir.is_dir():
        return None
    entries = sorted(p for p in capture_dir.iterdir() if p.name not in NOT_ARCHIVED)
    if not any(p.is_file() or (p.is_dir() and _has_file(p)) for p in entries):
        return None
    stamp = dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    dest = capture_dir / SUPERSEDED / stamp
    k = 1
    while dest.exists():
        dest = capture_dir / SUPERSEDED / f"{stamp}-{k}"
        k += 1
    dest.mkdir(parents=True)
    for p in entries:
        os.rename(p, dest / p.name)  # same file system: atomic, and dest / name is new
    log.warning("an earlier capture in %s was moved to %s (nothing deleted)", capture_dir, dest)
    return dest


def _has_file(folder: Path) -> bool:
    return any(not p.is_dir() for p in folder.rglob("*"))


# --------------------------------------------------------------------------- the capture lock


def _pid_alive(pid) -> bool:
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except (OverflowError, TypeError, ValueError, OSError):
        return False
    return True


def _read_holder(fd: int) -> dict | None:
    chunks = []
    offset = 0
    while chunk := os.pread(fd, 65536, offset):
        chunks.append(chunk)
        offset += len(chunk)
    text = b"".join(chunks).decode("utf-8", "replace").strip()
    if not text:
        return None
    try:
        holder = json.loads(text)
    except json.JSONDecodeError:
        return {"record": text[:200]}
    return holder if isinstance(holder, dict) else {"record": text[:200]}


def _describe(holder: dict | None) -> str:
    if not holder:
        return "a process that has not recorded itself yet"
    if "pid" not in holder:
        return f"an unreadable holder record ({holder.get('record')!r})"
    command = str(holder.get("command", "?"))
    if len(command) > 160:
        command = command[:160] + " ..."
    return (
        f"pid {holder['pid']} on host {holder.get('host', '?')}, started "
        f"{holder.get('started', '?')}, command: {command}"
    )


def _busy_message(path: Path, holder: dict | None) -> str:
    msg = (
        f"another capture is running in {path.parent}: {_describe(holder)}. It holds "
        f"{path}: wait for it to finish, or stop it"
    )
    pid = (holder or {}).get("pid")
    msg += f" (kill {pid}; the robot's motors stop with it)." if pid else "."
    if pid and holder.get("host") == socket.gethostname() and not _pid_alive(pid):
        msg += f" Process {pid} is gone, but a process it started still holds the lock."
    return msg + (
        " A capture that ends or is killed releases this lock by itself; if no capture runs "
        f"any more, find the process that keeps it with `fuser -v {path}`."
    )


def _check_takeover(path: Path, holder: dict, locked: bool) -> None:
    """An earlier holder recorded in the lock file did not release it: take it over when
    that process is gone (with a warning), refuse when this host cannot tell."""
    host = socket.gethostname()
    pid = holder.get("pid")
    if holder.get("host") != host:
        raise CaptureLockedError(
            f"the capture lock {path} names {_describe(holder)}; this host ({host}) cannot "
            "tell whether that capture still runs. If it does not (or to re-take the round "
            f"anyway), remove {path} and run the capture again."
        )
    if pid == os.getpid():
        return
    alive = _pid_alive(pid)
    if alive and not locked:  # no flock on this file system: the record is all there is
        raise CaptureLockedError(_busy_message(path, holder))
    log.warning(
        "the capture lock %s names %s, which ended without releasing it (killed?) %s: "
        "taking it over; what that capture wrote is moved to superseded/",
        path,
        _describe(holder),
        "and is no longer running" if not alive else "(its pid now runs another program)",
    )


def _command() -> str:
    argv = list(sys.argv)
    if argv and Path(argv[0]).name == "__main__.py" and Path(argv[0]).parent.name == "scenebot":
        return f"{Path(sys.executable).name} -m scenebot {shlex.join(argv[1:])}"
    return shlex.join(argv)


@contextlib.contextmanager
def capture_lock(capture_dir: Path) -> Iterator[dict]:
    """Hold the capture lock of ``capture_dir`` (one scene and round) while the body runs.

    The lock is an ``fcntl.flock`` on ``capture_dir/capture.lock``, which names the holder
    (pid, host, start time, command): the kernel releases it when the process ends, even by
    kill -9, so it never stays stuck; the holder record only makes the messages clear, and
    is emptied on release. It guards the photos also against ``snakemake --unlock`` while a
    capture runs.

    Yields:
        The holder record written.

    Raises:
        CaptureLockedError: another process holds it (the message names the process and
            what to do), or a holder on another host is recorded.
    """
    capture_dir = Path(capture_dir)
    capture_dir.mkdir(parents=True, exist_ok=True)
    path = capture_dir / LOCK_NAME
    fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
    try:
        locked = True
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise CaptureLockedError(_busy_message(path, _read_holder(fd))) from None
        except OSError as exc:  # e.g. ENOLCK: a file system without locks
            log.warning("%s cannot be locked (%s): relying on its holder record", path, exc)
            locked = False
        previous = _read_holder(fd)
        if previous:
            _check_takeover(path, previous, locked)
        me = {
            "pid": os.getpid(),
            "host": socket.gethostname(),
            "started": dt.datetime.now().isoformat(timespec="seconds"),
            "command": _command(),
            "cwd": os.getcwd(),
        }
        try:
            os.ftruncate(fd, 0)
            os.pwrite(fd, (json.dumps(me) + "\n").encode(), 0)
            os.fsync(fd)
        except OSError as exc:
            raise CaptureWriteError(
                f"could not write the capture lock {path}: {exc.strerror or exc} "
                f"({space_left(path)})"
            ) from None
        try:
            yield me
        finally:
            with contextlib.suppress(OSError):
                os.ftruncate(fd, 0)  # released: no holder recorded
    finally:
        os.close(fd)


# --------------------------------------------------------------------------- start and finish


def start_capture(capture_dir: Path, folders: tuple[str, ...] = ("images",)) -> Path | None:
    """Archive an earlier attempt (:func:`archive_previous`) and create the photo folders.
    Call it holding the :func:`capture_lock`. Returns the archive folder, if any."""
    dest = archive_previous(capture_dir)
    for name in folders:
        (Path(capture_dir) / name).mkdir(exist_ok=True)
    return dest


def stop_message(exc: BaseException, clog: CaptureLog, robot) -> BaseException | None:
    """Log ``exc`` as an ``error`` event (best effort: the disk may be full) and, for a
    photo or log that could not be written, the one clear error to stop the capture with."""
    try:
        clog.write({"type": "event", "t": robot.now, "event": "error", "error": repr(exc)})
    except (LogWriteError, OSError) as again:
        log.debug("the error could not be logged: %s", again)
    if not isinstance(exc, (PhotoWriteError, LogWriteError)):
        return None
    n = clog.counts.get("photo", 0)
    return type(exc)(
        f"{exc}. The capture stopped, motors stopped, after {n} photo(s); every photo in "
        f"{clog.path.name} is complete. Free some space (or point the results to a larger "
        "disk) and run the capture again: this attempt is kept in superseded/."
    )


def save_sim_state(capture_dir: Path, world, failing: bool) -> None:
    """:func:`scenebot.adaptive.write_sim_state`; when the capture is already failing, a
    failure here is only logged (the first error is the one to report)."""
    from scenebot.adaptive import write_sim_state

    try:
        write_sim_state(capture_dir, world)
    except OSError as exc:
        if failing:
            log.debug("could not save the simulator state: %s", exc)
            return
        raise CaptureWriteError(
            f"could not write {Path(capture_dir) / 'sim_state.json'}: {exc.strerror or exc} "
            f"({space_left(capture_dir)})"
        ) from None


def finish_capture(
    capture_dir: Path,
    plot: Callable[[Path, Path], object],
    photo_dirs: tuple[str, ...] = ("images",),
) -> Path:
    """Make the photos read-only, publish ``log.jsonl`` (a hard link to ``session.jsonl``)
    and draw ``session.png`` with ``plot(log, png)``, published as ``trajectory.png``.

    Returns:
        The ``log.jsonl`` path.
    """
    capture_dir = Path(capture_dir)
    for name in photo_dirs:
        for img in (capture_dir / name).glob("*.jpg"):
            img.chmod(stat.S_IRUSR | stat.S_IRGRP | stat.S_IROTH)
    session, out = capture_dir / SESSION_LOG, capture_dir / "log.jsonl"
    picture = capture_dir / SESSION_PICTURE
    tmp = capture_dir / f".{picture.stem}.{os.getpid()}.png"
    what = out
    try:
        if not (out.exists() and os.path.samefile(out, session)):
            os.link(session, out)
        what = picture
        plot(out, tmp)
        publish(tmp, picture)
        what = capture_dir / "trajectory.png"
        os.link(picture, what)
    except OSError as exc:
        hint = f" ({space_left(what)})" if exc.errno in (errno.ENOSPC, errno.EDQUOT) else ""
        raise CaptureWriteError(
            f"the capture's photos and log are complete, but {what} could not be written: "
            f"{exc.strerror or exc}{hint}"
        ) from None
    finally:
        tmp.unlink(missing_ok=True)
    return out


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
    from scenebot.explore import PhotoTaker, random_exploration, write_faults

    capture_dir = Path(capture_dir)
    with capture_lock(capture_dir):
        start_capture(capture_dir)
        robot, camera, world = make_backend(cfg, capture_dir)
        session = capture_dir / SESSION_LOG
        rng = np.random.default_rng([cfg.seed, round_index])
        failing = False
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
            try:
                result = random_exploration(robot, taker, clog, cfg.exploration, rng)
            except BaseException as exc:
                failing = True
                with contextlib.suppress(Exception):  # best effort: the faults recovered so far
                    write_faults(clog, robot)
                stop = stop_message(exc, clog, robot)
                if stop is not None:
                    raise stop from None
                raise
            finally:
                bar.close()
                robot.stop()
                save_sim_state(capture_dir, world, failing)
            summary = asdict(result)
            if world is not None:
                summary["max_penetration_m"] = world.max_penetration_m
            write_faults(clog, robot)
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
