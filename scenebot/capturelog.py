"""The capture log: ``round_{r}/capture/log.jsonl``, one JSON object per line.

Record types (field ``type``):

``session`` (first line)
    ``robot`` (backend name), ``scene``, ``round``, ``started`` (ISO time),
    ``camera``: ``{"width", "height", "focal_px", "model": "PINHOLE"}`` as configured (a real
    camera's EXIF is the authority; SfM reads EXIF, not this), ``config``: the stage config;
    adaptive rounds also ``map`` (the previous round's map) and ``map_sha1``
    (:func:`map_fingerprint`).
``photo``
    ``t`` (robot clock, s), ``index`` (0-based within the round), ``image`` (path relative to
    the capture folder, e.g. ``images/r000_0042.jpg``), ``odometry`` ``{x, y, theta}`` (m, rad,
    odometry frame, see :mod:`scenebot.robot.base`), ``compass_deg``, ``ultrasonic_cm``
    (255 = no echo), ``bump_front``, ``bump_rear``; in adaptive rounds (r >= 1) also
    ``localization`` ``{x, y, theta}`` (the robot's map-frame pose: this photo's visual fix,
    or the last fix carried forward by odometry, ``localization_source`` says which),
    ``localization_ok``, ``localization_inliers``, ``goal_index`` and ``requested_heading``;
    and for the simulator only ``truth``:
    ``{"robot": {x, y, theta}, "center": [x, y, z], "R_cam_from_world": 3x3 row-major}``
    in the world frame, camera axes as in OpenCV/COLMAP (x right, y down, z forward).
    ``truth`` is for evaluation only: no stage may read it to make a decision.
``event``
    ``t``, ``event`` (``bump``, ``stall``, ``drive``, ``turn``, ``circle_done``, ``backup``,
    ``error``, ...; adaptive rounds: ``follow_start``, ``localize``, ``localize_failed``,
    ``localize_rejected``, ``obstacle``, ``replan``, ``no_route``, ``follow_end`` with an
    ``estimate`` of the map-frame pose, and per goal attempt one of ``goal_reached``,
    ``goal_abandoned``, ``goal_skipped`` with ``goal_index``, ``goal``, ``reason`` and, for a
    backup goal tried in place of an abandoned one, ``backup_for``), ``odometry``, plus
    event-specific fields; simulator events carry ``truth`` with the robot pose.
``fault``
    ``t``, ``fault`` (``brick_reboot`` with ``during``, ``reply_lost``, ``reply_garbled``,
    ``link_lost``, ``watchdog_stop``, ``motor_start_resent``), ``recovered`` (true): a fault
    of the NXT link or brick that the driver recovered from, written before the next record.
``end`` (last line of a complete capture)
    ``t``, ``photos``, ``reason``.
"""

from __future__ import annotations

import contextlib
import json
import os
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from scenebot.jpeg import space_left


def json_default(o: Any) -> Any:
    """``json.dumps`` default for numpy values and paths (the logs and reports use it)."""
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"cannot write {type(o).__name__} as JSON")


class LogWriteError(RuntimeError):
    """A capture log record could not be written (disk full, I/O error): the capture stops.
    The log keeps every earlier record whole (a cut record is taken back)."""


class CaptureLog:
    """Append-only JSONL writer that writes and fsyncs every record whole (nothing lost on
    a crash, no half record on a full disk).

    Records go straight to the file descriptor (no buffer that could fail again on close);
    a record that cannot be written completely is cut off again, so the log stays readable
    and a later record never joins a half line.
    """

    def __init__(self, path: Path):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.counts: Counter[str] = Counter()
        """Records written by this writer, by ``type``."""
        try:
            self._fd: int | None = os.open(
                self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_CLOEXEC, 0o644
            )
        except OSError as exc:
            raise LogWriteError(
                f"could not open the capture log {self.path}: {exc.strerror or exc}"
            ) from None

    def fileno(self) -> int:
        if self._fd is None:
            raise ValueError(f"{self.path}: the capture log is closed")
        return self._fd

    def write(self, record: dict) -> None:
        """Append ``record`` as one line and fsync it.

        Raises:
            LogWriteError: it could not be written whole (the message says how much space
                is left); the log is as it was before.
        """
        data = (json.dumps(record, default=json_default, sort_keys=False) + "\n").encode()
        fd = self.fileno()
        start = os.fstat(fd).st_size
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view) :]
            os.fsync(fd)
            self.counts[str(record.get("type"))] += 1
        except OSError as exc:
            with contextlib.suppress(OSError):
                os.ftruncate(fd, start)  # take the cut record back
            raise LogWriteError(
                f"could not write to the capture log {self.path}: {exc.strerror or exc} "
                f"({space_left(self.path)})"
            ) from None

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> CaptureLog:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def read_log(path: Path) -> Iterator[dict]:
    """Yield the records of a capture log; a truncated last line (crash) is skipped."""
    path = Path(path)
    with open(path, encoding="utf-8") as fh:
        lines = fh.readlines()
    for i, line in enumerate(lines):
        line = line.strip()
        if not line:
            continue
        try:
            yield json.loads(line)
        except json.JSONDecodeError as exc:
            if i == len(lines) - 1:
                return  # a record cut off by a crash
            raise ValueError(f"{path}:{i + 1}: not a JSON record ({exc})") from exc


def photo_records(path: Path) -> list[dict]:
    """The ``photo`` records of a capture log, in order."""
    return [r for r in read_log(path) if r.get("type") == "photo"]


def map_fingerprint(sfm_dir: Path) -> str:
    """SHA-1 of a map's ``images.bin``: which map a round was driven with (the evaluation
    notices when that map has been rebuilt since)."""
    import hashlib

    return hashlib.sha1((Path(sfm_dir) / "images.bin").read_bytes()).hexdigest()


def write_faults(log: CaptureLog, robot) -> None:
    """Write the faults the robot recovered from since the last call as ``fault`` records
    (``{"type": "fault", "t", "fault", "recovered", ...}``; backends without
    ``drain_faults``, such as the simulator, have none)."""
    drain = getattr(robot, "drain_faults", None)
    if drain is not None:
        for record in drain():
            log.write(record)


def skipped_shots(path: str | Path) -> dict[int, str]:
    """The shots of the guide a person's round could not take (the capture log's
    ``shots_skipped`` events, from the inbox's ``skipped.json``): rank -> why."""
    out: dict[int, str] = {}
    for rec in read_log(path):
        if rec.get("event") == "shots_skipped":
            out |= {int(s["rank"]): str(s.get("reason") or "") for s in rec.get("shots", [])}
    return out
