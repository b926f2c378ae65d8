"""The NXT camera: a CHDK camera triggered by powering a motor port, photos uploaded by a
Wi-Fi SD card into an inbox folder.

``capture`` records the inbox contents, powers the camera port for ``pulse_s`` (switched off
again on every path), then waits for the first *new* ``.jpg`` whose size stayed the same for
``stable_polls`` polls, that starts with ``FF D8``, ends with ``FF D9`` and decodes, and moves
it atomically to the requested destination, never over an existing photo (:func:`move_atomic`;
a failed move raises :class:`~scenebot.jpeg.PhotoWriteError`). Files already in the inbox
before the trigger are never taken (a late photo of an earlier, timed-out capture cannot be
mistaken for this one if it was there at trigger time). Before the trigger, ``before_trigger``
runs (the robot's brick check: a reboot is found and recovered from before the photo, not
after it).
"""

from __future__ import annotations

import errno
import logging
import os
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from scenebot.jpeg import PhotoWriteError, publish, space_left, store_photo
from scenebot.robot.base import Camera, CameraError
from scenebot.robot.nxt.client import Clock, NxtClient, SystemClock
from scenebot.robot.nxt.config import NxtCameraConfig, motor_index
from scenebot.robot.nxt.protocol import (
    OutputMode,
    ProtocolError,
    RegulationMode,
    RunState,
    SetOutputState,
)
from scenebot.robot.nxt.robot import off_command

log = logging.getLogger(__name__)

JPEG_SUFFIXES = (".jpg", ".jpeg")


def is_complete_jpeg(data: bytes) -> bool:
    """SOI marker first, EOI marker last, and OpenCV decodes it."""
    if len(data) < 4 or data[:2] != b"\xff\xd8" or data[-2:] != b"\xff\xd9":
        return False
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_REDUCED_GRAYSCALE_2)
    return img is not None and img.size > 0


def move_atomic(src: Path, dest: Path) -> None:
    """Move the photo ``src`` to ``dest`` so ``dest`` appears complete or not at all, and
    never in place of an existing file.

    Same file system: ``src`` is fsynced and hard-linked as ``dest`` (fails if ``dest``
    exists), then its inbox name goes. Across file systems: copied to a temporary name next
    to ``dest``, fsynced, verified to decode, published the same way, then ``src`` goes.

    Raises:
        PhotoWriteError: ``dest`` exists, or the copy failed (disk full: the message says how
            much space is left); ``src`` stays in the inbox.
    """
    src, dest = Path(src), Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    if os.path.lexists(dest):
        raise PhotoWriteError(f"photo {dest} already exists: refusing to overwrite it")
    try:
        with open(src, "rb") as fh:
            os.fsync(fh.fileno())  # the uploader's data is on disk before it is a photo
        publish(src, dest)
        return
    except FileExistsError:
        raise PhotoWriteError(f"photo {dest} already exists: refusing to overwrite it") from None
    except OSError as exc:
        if exc.errno != errno.EXDEV:
            raise PhotoWriteError(
                f"could not move photo {src} to {dest}: {exc.strerror or exc} ({space_left(dest)})"
            ) from None

    def copy(tmp: Path) -> None:
        with open(src, "rb") as fi, open(tmp, "xb") as fo:
            shutil.copyfileobj(fi, fo)

    store_photo(dest, copy)
    os.unlink(src)


@dataclass
class _Seen:
    size: int
    stable: int


class NxtCamera(Camera):
    """Camera on an NXT motor port with a watched inbox.

    Args:
        client: the brick (shared with the robot).
        cfg: camera settings.
        clock: time source.
    """

    def __init__(self, client: NxtClient, cfg: NxtCameraConfig, clock: Clock | None = None):
        self.client, self.cfg = client, cfg
        self.clock = clock or client.clock or SystemClock()
        self.port = motor_index(cfg.port)
        self.inbox = Path(cfg.inbox)
        self._check_inbox()
        self.captured = 0
        self.before_trigger: Callable[[], None] | None = None  # e.g. NxtRobot.check_brick

    def _check_inbox(self) -> None:
        if not self.inbox.is_dir():
            raise CameraError(
                f"camera inbox folder {self.inbox} does not exist: create it and set the Wi-Fi "
                "SD card (or the emulator) to upload there, or fix nxt.camera.inbox"
            )

    def _jpegs(self) -> dict[str, os.stat_result]:
        out = {}
        with os.scandir(self.inbox) as it:
            for e in it:
                if e.is_file() and e.name.lower().endswith(JPEG_SUFFIXES):
                    try:
                        out[e.name] = e.stat()
                    except FileNotFoundError:
                        continue
        return out

    def trigger(self) -> None:
        """Power the camera port for ``pulse_s``; the port is switched off on every path."""
        on = SetOutputState(
            port=self.port,
            power=self.cfg.power,
            mode=OutputMode.MOTORON,
            regulation=RegulationMode.IDLE,
            turn_ratio=0,
            run_state=RunState.RUNNING,
            tacho_limit=0,
        )
        try:
            self.client.request(on)
            self.clock.sleep(self.cfg.pulse_s)
        finally:
            try:
                self.client.request(off_command(self.port))
            except ProtocolError as exc:
                log.error("could not switch the camera port off: %s", exc)
                raise

    def capture(self, dest: Path, timeout_s: float | None = None) -> Path:
        """Trigger, wait for the photo, move it to ``dest``; see the module doc.

        Raises:
            CameraError: inbox missing, ``dest`` exists, or no usable photo in time.
        """
        dest = Path(dest)
        timeout_s = self.cfg.timeout_s if timeout_s is None else timeout_s
        self._check_inbox()
        if dest.exists():
            raise CameraError(f"{dest} already exists: refusing to overwrite a photo")
        before = set(self._jpegs())
        t0 = self.clock.monotonic()
        try:
            if self.before_trigger is not None:
                self.before_trigger()
            self.trigger()
        except ProtocolError as exc:
            raise CameraError(
                f"could not trigger the camera on motor port {self.cfg.port} ({exc}): check the "
                "Bluetooth link and the brick's batteries"
            ) from exc
        seen: dict[str, _Seen] = {}
        rejected: set[str] = set()
        while True:
            now = {n: st for n, st in self._jpegs().items() if n not in before}
            for name in sorted(now, key=lambda n: (now[n].st_mtime_ns, n)):
                size = now[name].st_size
                s = seen.get(name)
                if s is None or s.size != size:
                    seen[name] = _Seen(size, 0)
                    rejected.discard(name)
                    continue
                s.stable += 1
                if s.stable < self.cfg.stable_polls or size == 0 or name in rejected:
                    continue
                src = self.inbox / name
                try:
                    data = src.read_bytes()
                except FileNotFoundError:
                    continue
                if len(data) != size or not is_complete_jpeg(data):
                    rejected.add(name)  # wait for it to change (upload paused mid-file)
                    continue
                move_atomic(src, dest)
                self.captured += 1
                return dest
            if self.clock.monotonic() - t0 > timeout_s:
                partial = ", ".join(sorted(seen)) or "none"
                raise CameraError(
                    f"no complete photo arrived in {self.inbox} within {timeout_s:.1f} s of the "
                    f"trigger (new files: {partial}): check the camera is on with the CHDK "
                    f"script running, the trigger cable on motor port {self.cfg.port}, and that "
                    "the Wi-Fi SD card uploads into this folder"
                )
            self.clock.sleep(self.cfg.poll_s)

    def close(self) -> None:
        """Switch the trigger line off (best effort)."""
        try:
            self.client.request(off_command(self.port))
        except Exception as exc:  # the link may already be closed
            log.info("camera close: %s", exc)
