"""Round-0 random exploration end to end through the NXT driver and the brick emulator on a
pty, backed by the simulator: the same artifacts as the ``sim`` backend."""

from __future__ import annotations

import numpy as np
import pytest

from scenebot.capture.explore import PhotoTaker, random_exploration
from scenebot.capturelog import CaptureLog, read_log
from scenebot.config import validate_config
from scenebot.robot.factory import make_emulator_world
from scenebot.robot.nxt import EmulatorConfig, NxtConfig
from scenebot.robot.nxt.backend import make_nxt_backend


@pytest.mark.slow
def test_random_exploration_through_nxt_emulator(tmp_path):
    cfg = validate_config(
        {"sim": {"camera": {"width": 160, "height": 120}}, "exploration": {"photos": 12}}
    )
    out = tmp_path / "round_000" / "capture"
    (out / "images").mkdir(parents=True)
    robot, camera = make_nxt_backend(
        NxtConfig(),
        world=make_emulator_world(cfg),
        inbox=out / "inbox",
        emulator=EmulatorConfig(time_scale=2.0),
    )
    emu = robot.emulator
    with CaptureLog(out / "log.jsonl") as log, robot:
        log.write({"type": "session", "t": robot.now, "robot": "nxt-emulated", "round": 0})
        taker = PhotoTaker(robot, camera, log, out, "r000")
        result = random_exploration(
            robot, taker, log, cfg.exploration, np.random.default_rng([cfg.seed, 0])
        )
        log.write({"type": "end", "t": robot.now, "photos": result.photos, "reason": "budget"})
    assert result.photos == 12
    assert not emu.motors_running() and emu.error is None and not emu.render_errors
    records = list(read_log(out / "log.jsonl"))
    photos = [r for r in records if r["type"] == "photo"]
    assert [p["index"] for p in photos] == list(range(12))
    images = sorted((out / "images").glob("*.jpg"))
    assert [f"images/{p.name}" for p in images] == [p["image"] for p in photos]
    # no photo lost or duplicated: every rendered photo arrived once, the inbox is empty
    assert len(emu.photos) == 12 and list((out / "inbox").iterdir()) == []
    assert len({p.read_bytes() for p in images}) == 12
    for p in photos:
        assert {"odometry", "compass_deg", "ultrasonic_cm", "truth"} <= p.keys()
        assert 0.0 <= p["compass_deg"] < 360.0
    # odometry (wheel encoders over the wire) agrees with the true robot heading/position
    truth = [p["truth"]["robot"] for p in photos]
    d_odo = np.hypot(photos[-1]["odometry"]["x"], photos[-1]["odometry"]["y"])
    d_true = np.hypot(truth[-1]["x"] - truth[0]["x"], truth[-1]["y"] - truth[0]["y"])
    assert abs(d_odo - d_true) < 0.1
    # within a circle the compass (converted from the emulated clockwise sensor) tracks truth
    for p, t in zip(photos, truth, strict=True):
        err = p["compass_deg"] - np.degrees(t["theta"]) + cfg.sim.sensors.compass_offset_deg
        err = (err + 180.0) % 360.0 - 180.0
        assert abs(err) < 4.0 * cfg.sim.sensors.compass_noise_deg + 1.0


@pytest.mark.slow
def test_reboot_right_after_the_third_photo(tmp_path):
    """Issue 24, case 2: the brick reboots right after the 3rd camera trigger. The turn that
    follows must detect it before reading the wheel counters: every odometry step of the
    circle stays the commanded step, the robot really turns, and the log records the fault."""
    cfg = validate_config(
        {"sim": {"camera": {"width": 160, "height": 120}}, "exploration": {"photos": 6}}
    )
    out = tmp_path / "round_000" / "capture"
    (out / "images").mkdir(parents=True)
    robot, camera = make_nxt_backend(
        NxtConfig(), world=make_emulator_world(cfg), inbox=out / "inbox",
        emulator=EmulatorConfig(time_scale=2.0),
    )  # fmt: skip
    emu = robot.emulator
    trigger = camera.trigger

    def trigger_then_reboot():
        trigger()
        if camera.captured == 2:  # the 3rd trigger (captured counts finished photos)
            emu.cfg.faults.reboot_at.append(emu.command_count)

    camera.trigger = trigger_then_reboot
    with CaptureLog(out / "log.jsonl") as log, robot:
        taker = PhotoTaker(robot, camera, log, out, "r000")
        result = random_exploration(
            robot, taker, log, cfg.exploration, np.random.default_rng([cfg.seed, 0])
        )
    assert result.photos == 6 and emu.reboots == 1
    assert not emu.motors_running()
    records = list(read_log(out / "log.jsonl"))
    faults = [r for r in records if r["type"] == "fault"]
    assert [f["fault"] for f in faults] == ["brick_reboot"] and faults[0]["during"] == "turn"
    photos = [r for r in records if r["type"] == "photo"]
    step = np.radians(cfg.exploration.circle_step_deg)
    odo = np.unwrap([p["odometry"]["theta"] for p in photos])
    true = np.unwrap([p["truth"]["robot"]["theta"] for p in photos])
    assert np.allclose(np.diff(odo), step, atol=np.radians(0.5))  # was 10.2, 10.1, -20.3, ...
    assert np.all(np.diff(true) > 0.5 * step)  # the turn after the reboot happened
    assert len({(out / p["image"]).read_bytes() for p in photos}) == 6
