"""What every capture does with its folder (round 0 in :mod:`scenebot.capture.stage`, the adaptive
rounds in :mod:`scenebot.capture.adaptive`): the lock, the archive of an earlier attempt, the first
record of the log, the stop on an error, the finish.

A capture writes into ``results/{scene}/round_{r}/capture/``:

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
import os
import shlex
import socket
import stat
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

from scenebot.capturelog import CaptureLog, LogWriteError, write_faults
from scenebot.config import Config
from scenebot.jpeg import PhotoWriteError, publish, space_left

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


def archive_previous(capture_dir: Path, keep: tuple[str, ...] = ()) -> Path | None:
    """Move everything an earlier attempt wrote to ``superseded/<time>/`` (never delete).

    Every entry of ``capture_dir`` but ``superseded/``, the lock and ``keep`` (a person's
    ``inbox/``: the photos are the person's, not the attempt's) moves, by rename, to
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
    entries = sorted(p for p in capture_dir.iterdir() if p.name not in (*NOT_ARCHIVED, *keep))
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


def start_capture(
    capture_dir: Path, folders: tuple[str, ...] = ("images",), keep: tuple[str, ...] = ()
) -> Path | None:
    """Archive an earlier attempt (:func:`archive_previous`, leaving ``keep`` in place) and
    create the photo folders. Call it holding the :func:`capture_lock`. Returns the archive
    folder, if any."""
    dest = archive_previous(capture_dir, keep)
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
    """:func:`scenebot.robot.sim.write_sim_state` (the simulator backend's state for the next
    round); when the capture is already failing, a failure here is only logged (the first
    error is the one to report)."""
    from scenebot.robot.sim import SIM_STATE, write_sim_state

    try:
        write_sim_state(capture_dir, world)
    except OSError as exc:
        if failing:
            log.debug("could not save the simulator state: %s", exc)
            return
        raise CaptureWriteError(
            f"could not write {Path(capture_dir) / SIM_STATE}: {exc.strerror or exc} "
            f"({space_left(capture_dir)})"
        ) from None


@contextlib.contextmanager
def stopping_safely(clog: CaptureLog, robot, capture_dir: Path, world, bar) -> Iterator[None]:
    """The body of a capture: on any way out the progress bar closes, the robot stops and the
    simulator's state is saved; on an error the faults recovered so far are logged and a
    known failure (a full disk, a lost link) becomes one clear message (:func:`stop_message`).
    """
    failing = False
    try:
        yield
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
