"""Nothing lost, nothing stuck (issue 24, items 1, 4 and 5).

* A re-take (a killed or forced capture run again) archives every file the earlier attempt
  wrote, byte for byte, and the archived log still points at the archived photos.
* A photo is never overwritten, and is stored atomically and verified before it is logged;
  a full disk stops the capture with one clear message and the motors stopped.
* A capture lock of scenebot's own: a second capture of the same round is refused, naming
  the holder; a lock left by a killed capture is taken over with a warning.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import signal
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from scenebot.capture.session import archive_previous
from scenebot.capture.stage import run_capture
from scenebot.capturelog import CaptureLog, photo_records, read_log
from scenebot.config import validate_config
from scenebot.robot.base import Health, Pose2D, Robot, SensorReading


def small_cfg(photos=6, **over):
    data = {"sim": {"camera": {"width": 80, "height": 60}}, "exploration": {"photos": photos}}
    data.update(over)
    return validate_config(data)


def hashes(folder: Path, skip=("superseded", "capture.lock")) -> dict[str, str]:
    """sha256 of every file under ``folder`` by relative path (``skip``: top-level names)."""
    out = {}
    for p in sorted(Path(folder).rglob("*")):
        rel = p.relative_to(folder)
        if p.is_file() and rel.parts[0] not in skip:
            out[rel.as_posix()] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def jpeg_bytes(seed: int, size=(40, 30)) -> bytes:
    import io

    rgb = np.random.default_rng(seed).integers(0, 255, (size[1], size[0], 3), np.uint8)
    buf = io.BytesIO()
    Image.fromarray(rgb).save(buf, "JPEG")
    return buf.getvalue()


def decodes(path: Path) -> bool:
    try:
        with Image.open(path) as im:
            im.load()
        return True
    except OSError:
        return False


# ---------------------------------------------------------------------------- item 1: re-takes


def fake_adaptive_capture(cap: Path) -> None:
    """What an adaptive round leaves behind when it is killed late (or has finished)."""
    (cap / "images").mkdir(parents=True)
    (cap / "nav").mkdir()
    (cap / "inbox").mkdir()
    recs = [{"type": "session", "round": 1}]
    for i in range(3):
        (cap / "nav" / f"nav_g000_{i:04d}.jpg").write_bytes(jpeg_bytes(i))
        recs.append({"type": "event", "event": "localize", "image": f"nav/nav_g000_{i:04d}.jpg"})
    for i in range(2):
        (cap / "images" / f"r001_{i:04d}.jpg").write_bytes(jpeg_bytes(10 + i))
        recs.append({"type": "photo", "index": i, "image": f"images/r001_{i:04d}.jpg"})
    (cap / "session.jsonl").write_text("".join(json.dumps(r) + "\n" for r in recs))
    os.link(cap / "session.jsonl", cap / "log.jsonl")
    (cap / "session.png").write_bytes(b"\x89PNG picture")
    os.link(cap / "session.png", cap / "trajectory.png")
    (cap / "sim_state.json").write_text('{"robot": {"x": 1, "y": 2, "theta": 0}}')
    (cap / "inbox" / "IMG_0042.JPG").write_bytes(jpeg_bytes(42))  # arrived too late
    (cap / "notes.txt").write_text("anything else the capture wrote")


def test_a_retake_archives_every_file_of_an_adaptive_round_and_its_log_still_resolves(tmp_path):
    cap = tmp_path / "round_001" / "capture"
    fake_adaptive_capture(cap)
    before = hashes(cap)
    dest = archive_previous(cap)
    assert dest is not None and dest.parent == cap / "superseded"
    assert hashes(cap) == {}, "files left in place would be overwritten by the re-take"
    assert hashes(dest) == before  # every file, byte for byte, same relative path
    for rec in read_log(dest / "log.jsonl"):
        if "image" in rec:
            archived = dest / rec["image"]
            assert archived.is_file() and hashes(dest)[rec["image"]] == before[rec["image"]]
    assert os.path.samefile(dest / "log.jsonl", dest / "session.jsonl")


def test_a_forced_rerun_of_a_round_loses_no_file(tmp_path):
    """Snakemake's --forcerun first deletes the rule's outputs (log.jsonl, trajectory.png),
    then the capture runs again: every file of the first attempt must survive."""
    cap = tmp_path / "round_000" / "capture"
    run_capture(small_cfg(), cap, progress=False)
    first = hashes(cap)
    assert any(k.startswith("images/") for k in first) and "sim_state.json" in first
    pictures = {first[k] for k in ("trajectory.png",)}
    (cap / "log.jsonl").unlink()  # what snakemake does before a forced re-run
    (cap / "trajectory.png").unlink()
    run_capture(small_cfg(seed=5), cap, progress=False)
    (archived,) = (cap / "superseded").iterdir()
    kept = hashes(archived)
    missing = set(first.values()) - set(kept.values())
    assert not missing, f"{len(missing)} files of the first attempt lost"
    assert pictures <= set(kept.values())  # the trajectory picture too
    for rec in photo_records(archived / "session.jsonl"):
        assert decodes(archived / rec["image"])
        assert kept[rec["image"]] == first[rec["image"]]
    # the re-take is complete in place
    assert (cap / "log.jsonl").is_file() and (cap / "trajectory.png").is_file()


class StillRobot(Robot):
    """A robot that stays where it is (the follower only takes a photo here)."""

    def __init__(self):
        self.t = 0.0

    def drive(self, distance_m):
        raise AssertionError("not used")

    def turn(self, angle_rad):
        raise AssertionError("not used")

    def stop(self):
        pass

    def sense(self):
        return SensorReading(self.t, 0.0, 255, False, False, Pose2D(0.0, 0.0, 0.0))

    def health(self):
        return Health(8000, True)

    @property
    def now(self):
        return self.t


def test_the_follower_logs_nav_photos_relative_to_the_capture_folder(tmp_path, monkeypatch):
    """An archived log must point at the archived nav photos, not at the live folder."""
    from scenebot.capture.follow import PathFollower
    from scenebot.localize.locate import FailureReason, LocalizationFailure

    class Cam:
        def capture(self, dest, timeout_s=None):
            Path(dest).write_bytes(jpeg_bytes(1))
            return Path(dest)

    cap = tmp_path / "capture"
    monkeypatch.chdir(tmp_path)
    with CaptureLog(Path("capture") / "session.jsonl") as log:
        fail = LocalizationFailure(FailureReason.TOO_FEW_MATCHES, 0, 0, 0)
        f = PathFollower(StillRobot(), Cam(), lambda p: fail, planner=None,
                         photo_dir=Path("capture") / "nav", log=log)  # fmt: skip
        (cap / "nav").mkdir()
        f.localize_now()
    (rec,) = [r for r in read_log(cap / "session.jsonl") if "image" in r]
    assert rec["image"] == "nav/nav_g000_0000.jpg"
    assert (cap / rec["image"]).is_file()


# ---------------------------------------------------------------------------- never overwrite


def test_the_sim_camera_never_overwrites_a_photo(tmp_path, room, sim_cfg):
    from scenebot.jpeg import PhotoWriteError
    from scenebot.robot.sim import SimCamera
    from scenebot.sim.world import SimWorld

    cam = SimCamera(SimWorld(room, sim_cfg, room.start, seed=1))
    dest = tmp_path / "images" / "r000_0000.jpg"
    dest.parent.mkdir()
    dest.write_bytes(b"an earlier photo")
    with pytest.raises(PhotoWriteError, match=r"r000_0000\.jpg.*exists"):
        cam.capture(dest)
    assert dest.read_bytes() == b"an earlier photo"
    assert sorted(p.name for p in dest.parent.iterdir()) == ["r000_0000.jpg"]  # no leftovers
    new = cam.capture(dest.with_name("r000_0001.jpg"))
    assert decodes(new)


def test_the_nxt_inbox_move_never_overwrites_a_photo(tmp_path):
    from scenebot.jpeg import PhotoWriteError
    from scenebot.robot.nxt.camera import move_atomic

    src, dest = tmp_path / "IMG_0001.JPG", tmp_path / "images" / "r000_0000.jpg"
    src.write_bytes(jpeg_bytes(1))
    dest.parent.mkdir()
    dest.write_bytes(jpeg_bytes(2))
    with pytest.raises(PhotoWriteError, match="exists"):
        move_atomic(src, dest)
    assert src.read_bytes() == jpeg_bytes(1) and dest.read_bytes() == jpeg_bytes(2)


# ---------------------------------------------------------------------------- item 4: full disk


def _failing_save(monkeypatch, fail_at: int, how: str):
    """Make the ``fail_at``-th JPEG save (0-based) fail as a full disk does: ``raise`` an
    ENOSPC, or ``short`` (write part of the file and return without an error, as PIL does
    when the disk fills during its last write)."""
    orig = Image.Image.save
    calls = {"n": 0}

    def save(self, fp, *args, **kw):
        k = calls["n"]
        calls["n"] += 1
        if k < fail_at:
            return orig(self, fp, *args, **kw)
        if how == "raise":
            Path(fp).write_bytes(b"\xff\xd8\xff")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        orig(self, fp, *args, **kw)
        data = Path(fp).read_bytes()
        Path(fp).write_bytes(data[: len(data) // 2])

    monkeypatch.setattr(Image.Image, "save", save)


@pytest.mark.parametrize("how", ["raise", "short"])
def test_a_full_disk_stops_the_capture_with_one_message_and_logs_no_broken_photo(
    tmp_path, monkeypatch, how
):
    from scenebot.jpeg import PhotoWriteError
    from scenebot.robot.sim import SimRobot

    stops = []
    orig_stop = SimRobot.stop
    monkeypatch.setattr(SimRobot, "stop", lambda self: (stops.append(1), orig_stop(self)))
    cap = tmp_path / "round_000" / "capture"
    _failing_save(monkeypatch, fail_at=3, how=how)
    with pytest.raises(PhotoWriteError) as err:
        run_capture(small_cfg(), cap, progress=False)
    msg = str(err.value)
    assert "images/r000_0003.jpg" in msg and "free" in msg and "motors stopped" in msg
    assert err.value.__cause__ is None and err.value.__suppress_context__  # no chain
    assert stops
    photos = photo_records(cap / "session.jsonl")
    assert [p["image"] for p in photos] == [f"images/r000_{i:04d}.jpg" for i in range(3)]
    assert all(decodes(cap / p["image"]) for p in photos)
    assert sorted(p.name for p in (cap / "images").iterdir()) == [
        f"r000_{i:04d}.jpg" for i in range(3)
    ]  # no truncated photo, no temporary file left
    assert read_log(cap / "session.jsonl")  # still a readable log


def test_the_cli_reports_a_full_disk_in_one_line(tmp_path, monkeypatch, capsys):
    from scenebot.cli import main

    _failing_save(monkeypatch, fail_at=2, how="raise")
    params = json.dumps(small_cfg().model_dump(mode="json", include={"sim", "exploration"}))
    assert main(["capture", "--params", params, "--out", str(tmp_path / "c"),
                 "--no-progress"]) == 1  # fmt: skip
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error")]
    assert len(err) == 1 and "r000_0002.jpg" in err[0] and "No space left" in err[0]


def test_a_full_disk_under_the_capture_log_keeps_it_readable(tmp_path, monkeypatch):
    from scenebot.capturelog import LogWriteError

    path = tmp_path / "session.jsonl"
    log = CaptureLog(path)
    log.write({"type": "session"})
    good = path.read_bytes()
    orig = os.write

    def half_then_full(fd, data):
        if fd == log.fileno():
            orig(fd, bytes(data)[: len(data) // 2])
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return orig(fd, data)

    monkeypatch.setattr(os, "write", half_then_full)
    with pytest.raises(LogWriteError, match=r"session\.jsonl.*No space left.*free"):
        log.write({"type": "photo", "image": "images/a.jpg"})
    monkeypatch.undo()
    log.close()
    assert path.read_bytes() == good  # the cut record was taken back: no broken line


# ---------------------------------------------------------------------------- item 5: the lock

HOLDER = textwrap.dedent(
    """
    import sys, time
    from pathlib import Path
    from scenebot.capture.session import capture_lock
    with capture_lock(Path(sys.argv[1])):
        print("locked", flush=True)
        time.sleep(120)
    """
)


def _hold_lock(folder: Path) -> subprocess.Popen:
    env = dict(os.environ, TI_SKIP_VERSION_CHECK="ON")
    proc = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(folder)], stdout=subprocess.PIPE, text=True, env=env
    )
    line = proc.stdout.readline()
    assert line.strip() == "locked", line
    return proc


def test_a_second_capture_of_a_round_is_refused_naming_the_holder(tmp_path):
    from scenebot.capture.session import CaptureLockedError

    cap = tmp_path / "round_000" / "capture"
    run_capture(small_cfg(), cap, progress=False)
    before = hashes(cap)
    holder = _hold_lock(cap)
    try:
        with pytest.raises(CaptureLockedError) as err:
            run_capture(small_cfg(seed=3), cap, progress=False)
    finally:
        holder.kill()
        holder.wait()
    msg = str(err.value)
    assert f"pid {holder.pid}" in msg and socket.gethostname() in msg and "kill" in msg
    assert hashes(cap) == before and not (cap / "superseded").exists()  # nothing touched


def test_a_lock_left_by_a_killed_capture_is_taken_over_with_a_warning(tmp_path, caplog):
    cap = tmp_path / "round_000" / "capture"
    cap.mkdir(parents=True)
    holder = _hold_lock(cap)
    os.kill(holder.pid, signal.SIGKILL)  # kill -9 leaves no stuck lock
    holder.wait()
    with caplog.at_level("WARNING", logger="scenebot.capture.stage"):
        run_capture(small_cfg(), cap, progress=False)
    assert any(
        f"pid {holder.pid}" in r.getMessage() and "taking it over" in r.getMessage()
        for r in caplog.records
    )
    assert len(photo_records(cap / "log.jsonl")) == 6


def test_a_lock_held_on_another_host_is_not_taken_over(tmp_path):
    from scenebot.capture.session import LOCK_NAME, CaptureLockedError

    cap = tmp_path / "capture"
    cap.mkdir()
    holder = {"pid": 4242, "host": "robot-laptop", "started": "2026-11-26T10:00:00",
              "command": "scenebot capture --out x"}  # fmt: skip
    (cap / LOCK_NAME).write_text(json.dumps(holder))
    with pytest.raises(CaptureLockedError, match=r"pid 4242 on host robot-laptop.*remove"):
        run_capture(small_cfg(), cap, progress=False)


def test_the_lock_is_released_when_the_capture_ends(tmp_path):
    from scenebot.capture.session import capture_lock

    cap = tmp_path / "capture"
    run_capture(small_cfg(), cap, progress=False)
    t0 = time.monotonic()
    with capture_lock(cap) as me:  # free again, and no warning about a stale holder
        assert me["pid"] == os.getpid()
    assert time.monotonic() - t0 < 1.0
