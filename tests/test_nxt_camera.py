"""The NXT camera: trigger pulse bytes and the inbox watcher (injected clock, no sleeping)."""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np
import pytest

from scenebot.robot.base import CameraError
from scenebot.robot.nxt import protocol as p
from scenebot.robot.nxt.camera import NxtCamera, is_complete_jpeg, move_atomic
from scenebot.robot.nxt.config import NxtCameraConfig


def jpeg(seed: int) -> bytes:
    rng = np.random.default_rng(seed)
    img = rng.integers(0, 255, (48, 64, 3), dtype=np.uint8)
    ok, buf = cv2.imencode(".jpg", img)
    assert ok
    return buf.tobytes()


class Uploader:
    """A fake clock that plays the Wi-Fi card: ``plan`` maps a time to file writes."""

    def __init__(self, inbox: Path):
        self.t = 0.0
        self.inbox = inbox
        self.plan: list[tuple[float, str, bytes]] = []

    def monotonic(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        self.t += s
        due = [e for e in self.plan if e[0] <= self.t]
        self.plan = [e for e in self.plan if e[0] > self.t]
        for _, name, data in due:
            path = self.inbox / name
            with open(path, "ab") as fh:
                fh.write(data)
            # distinct, increasing mtimes regardless of the file system's timestamp resolution
            ns = int(1e9 * (1000 + self.t))
            os.utime(path, ns=(ns, ns))

    def upload(self, start: float, name: str, data: bytes, chunks: int, gap: float) -> None:
        n = -(-len(data) // chunks)
        for k in range(chunks):
            self.plan.append((start + k * gap, name, data[k * n : (k + 1) * n]))


class RecordingClient:
    def __init__(self, clock):
        self.clock = clock
        self.sent: list[tuple[float, p.Command]] = []

    def request(self, cmd):
        self.sent.append((self.clock.t, cmd))
        return p.StatusReply(opcode=int(cmd.OPCODE))


def make(tmp_path, **kw):
    inbox = tmp_path / "inbox"
    inbox.mkdir()
    clock = Uploader(inbox)
    client = RecordingClient(clock)
    cfg = NxtCameraConfig(inbox=inbox, **kw)
    return NxtCamera(client, cfg, clock), client, clock, inbox


def test_trigger_pulse_bytes_and_duration(tmp_path):
    cam, client, clock, _ = make(tmp_path, pulse_s=0.3, port="A")
    clock.upload(0.5, "IMG_0001.JPG", jpeg(1), 3, 0.1)
    cam.capture(tmp_path / "out" / "a.jpg")
    (t_on, on), (t_off, off) = client.sent
    assert on.packet() == bytes.fromhex("0c00 00 04 00 64 01 00 00 20 00000000")
    assert off.packet() == bytes.fromhex("0c00 00 04 00 00 00 00 00 00 00000000")
    assert t_off - t_on == pytest.approx(0.3)


def test_takes_first_new_complete_jpeg_and_ignores_old_files(tmp_path):
    cam, _, clock, inbox = make(tmp_path)
    old = jpeg(0)
    (inbox / "OLD.JPG").write_bytes(old)
    (inbox / "notes.txt").write_text("not a photo")
    first, second = jpeg(1), jpeg(2)
    clock.upload(0.4, "IMG_0001.JPG", first, 5, 0.05)
    clock.upload(0.9, "IMG_0002.JPG", second, 2, 0.05)
    dest = cam.capture(tmp_path / "cap" / "p0.jpg")
    assert dest.read_bytes() == first
    assert not (inbox / "IMG_0001.JPG").exists() and (inbox / "OLD.JPG").read_bytes() == old
    dest2 = cam.capture(tmp_path / "cap" / "p1.jpg")  # the second photo is not lost
    assert dest2.read_bytes() == second


def test_waits_for_size_to_settle_and_rejects_truncated(tmp_path):
    cam, _, clock, _ = make(tmp_path, stable_polls=2, poll_s=0.05)
    data = jpeg(3)
    # the upload pauses for 0.5 s after half the file: stable but no EOI -> must not be taken
    half = len(data) // 2
    clock.plan = [(0.4, "IMG_0003.JPG", data[:half]), (0.9, "IMG_0003.JPG", data[half:])]
    dest = cam.capture(tmp_path / "c.jpg")
    assert dest.read_bytes() == data
    assert clock.t >= 0.9


def test_timeout_is_clear_error_and_port_is_off(tmp_path):
    cam, client, _, _inbox = make(tmp_path, timeout_s=2.0)
    with pytest.raises(CameraError, match=r"CHDK.*motor port A.*Wi-Fi"):
        cam.capture(tmp_path / "x.jpg")
    assert client.sent[-1][1].power == 0 and client.sent[-1][1].mode == 0


def test_corrupt_photo_never_accepted(tmp_path):
    cam, _, clock, _ = make(tmp_path, timeout_s=1.5)
    bad = b"\xff\xd8" + bytes(500) + b"\xff\xd9"  # right markers, does not decode
    clock.upload(0.4, "IMG_0009.JPG", bad, 1, 0.0)
    with pytest.raises(CameraError, match=r"IMG_0009.JPG"):
        cam.capture(tmp_path / "x.jpg")


def test_missing_inbox_and_existing_dest(tmp_path):
    clock = Uploader(tmp_path)
    with pytest.raises(CameraError, match=r"inbox folder .* does not exist"):
        NxtCamera(RecordingClient(clock), NxtCameraConfig(inbox=tmp_path / "nope"), clock)
    cam, client, _, _ = make(tmp_path)
    (tmp_path / "taken.jpg").write_bytes(b"x")
    with pytest.raises(CameraError, match="already exists"):
        cam.capture(tmp_path / "taken.jpg")
    assert client.sent == []  # no trigger when the destination is wrong


def test_trigger_switches_off_when_interrupted(tmp_path):
    cam, client, clock, _ = make(tmp_path)

    def boom(s):
        raise KeyboardInterrupt

    clock.sleep = boom
    with pytest.raises(KeyboardInterrupt):
        cam.capture(tmp_path / "k.jpg")
    assert [c.power for _, c in client.sent] == [100, 0]


def test_is_complete_jpeg_and_move_atomic(tmp_path):
    data = jpeg(5)
    assert is_complete_jpeg(data)
    assert not is_complete_jpeg(data[:-2]) and not is_complete_jpeg(data[1:])
    src = tmp_path / "a.jpg"
    src.write_bytes(data)
    move_atomic(src, tmp_path / "sub" / "b.jpg")
    assert not src.exists() and (tmp_path / "sub" / "b.jpg").read_bytes() == data
