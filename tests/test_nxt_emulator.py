"""The brick emulator on a real pty: exact bytes through pyserial, the driver against it,
every injected fault, bad input, and the safety paths (motors off on every exit)."""

from __future__ import annotations

import _thread
import contextlib
import math
import os
import signal
import threading
import time
from pathlib import Path

import pytest
import serial

from scenebot.robot.base import CameraError, LinkLostError, MotionStatus, Pose2D
from scenebot.robot.nxt import EmulatorConfig, FaultConfig, NxtConfig, connect, make_nxt_robot
from scenebot.robot.nxt import protocol as p
from scenebot.robot.nxt.camera import NxtCamera
from scenebot.robot.nxt.client import BrickNotAnsweringError, PortBusyError, PortNotFoundError
from scenebot.robot.nxt.emulator import NxtEmulator
from scenebot.robot.nxt.robot import Terminated, install_sigterm_handler
from tests.fixtures.boxworld import BoxWorld

SCALE = 3.0  # simulated seconds per wall second


def h(s: str) -> bytes:
    return bytes.fromhex(s)


@contextlib.contextmanager
def brick(tmp_path: Path, world=None, **emu):
    inbox = tmp_path / "inbox"
    inbox.mkdir(exist_ok=True)
    world = world or BoxWorld()
    emu.setdefault("time_scale", SCALE)
    with NxtEmulator(world, EmulatorConfig(inbox=inbox, **emu), NxtConfig()) as e:
        yield e


def exchange(port: serial.Serial, packet: bytes, n: int) -> bytes:
    port.write(packet)
    out = b""
    deadline = time.monotonic() + 2.0
    while len(out) < n and time.monotonic() < deadline:
        out += port.read(n - len(out))
    return out


def test_emulator_exact_bytes_over_pty(tmp_path):
    with brick(tmp_path, battery_mv=7890, sleep_limit_s=600) as emu:
        with serial.Serial(emu.port_path, timeout=0.05) as s:
            assert exchange(s, h("0200 00 0d"), 9) == h("0700 02 0d 00 c0270900")
            assert exchange(s, h("0200 00 0b"), 7) == h("0500 02 0b 00 d21e")
            assert exchange(s, h("0300 00 06 01"), 27) == h("1900 02 06 00 01") + bytes(21)
            assert exchange(s, h("0500 00 05 00 01 20"), 5) == h("0300 02 05 00")
            assert exchange(s, h("0300 00 07 00"), 18) == h("1000 02 07 00 00 01 00 01 20") + h(
                "ff03 ff03 0000 0000"
            )
            # digital port: 0xE0 right after the mode change (LSWRITE and LSREAD alike)
            assert exchange(s, h("0500 00 05 03 0b 00"), 5) == h("0300 02 05 00")
            assert exchange(s, h("0700 00 0f 03 02 01 02 42"), 5) == h("0300 02 0f e0")
            assert exchange(s, h("0300 00 10 03"), 22) == h("1400 02 10 e0") + bytes(17)
            time.sleep(0.05)
            assert exchange(s, h("0700 00 0f 03 02 01 02 42"), 5) == h("0300 02 0f 00")
            time.sleep(0.01)
            assert exchange(s, h("0300 00 0e 03"), 6) == h("0400 02 0e 00 01")
            assert exchange(s, h("0300 00 10 03"), 22) == h("1400 02 10 00 01 96") + bytes(15)
            # errors: bad output port, unknown opcode, wrong size
            assert exchange(s, h("0c00 00 04 07 00 00 00 00 00 00000000"), 5) == h("0300 02 04 c0")
            assert exchange(s, h("0200 00 55"), 5) == h("0300 02 55 be")
            assert exchange(s, h("0400 00 06 01 02"), 5) == h("0300 02 06 ed")
            # no reply wanted: nothing comes back; the command still acts
            s.write(h("0c00 80 04 00 64 01 00 00 20 00000000"))
            time.sleep(0.05)
            assert s.in_waiting == 0
            assert emu.motors[0].powered and emu.motors[0].power == 100
            assert exchange(s, h("0c00 00 04 ff 00 00 00 00 00 00000000"), 5) == h("0300 02 04 00")
            assert not emu.motors_running()
        assert emu.error is None


def robot_on_emulator(tmp_path, world=None, faults=None, emu=None, **cfg):
    cfg.setdefault("camera", {"inbox": str(tmp_path / "inbox")})
    cfg.setdefault("battery_check_interval_s", 1e6)
    ecfg = EmulatorConfig(**{"time_scale": SCALE, "faults": faults or FaultConfig(), **(emu or {})})
    return make_nxt_robot(NxtConfig(**cfg), world=world or BoxWorld(), emulator=ecfg, sigterm=False)


def test_drive_turn_capture_against_truth(tmp_path):
    world = BoxWorld()
    robot, cam = robot_on_emulator(tmp_path, world)
    with robot:
        r = robot.drive(0.4)
        assert r.status is MotionStatus.COMPLETED
        assert r.distance_m == pytest.approx(0.4, abs=0.003)  # the brick stops at the limit
        assert world.truth_pose.x == pytest.approx(0.4, abs=0.01)
        r = robot.turn(math.pi / 2)
        assert r.status is MotionStatus.COMPLETED and r.angle_rad == pytest.approx(
            math.pi / 2, abs=0.05
        )
        assert world.truth_pose.theta == pytest.approx(math.pi / 2, abs=0.05)
        s = robot.sense()
        assert s.compass_deg == pytest.approx(90.0, abs=1.0)  # converted from clockwise
        assert s.ultrasonic_cm == round(100 * (world.params.half_y_m - world.truth_pose.y))
        assert s.odometry.x == pytest.approx(world.truth_pose.x, abs=0.01)
        photo = cam.capture(tmp_path / "cap" / "p0.jpg")
        assert photo.read_bytes()[:2] == b"\xff\xd8"
        health = robot.health()
        assert health.battery_mv == 8100 and health.link_ok
        assert health.details["reboots"] == 0
    assert not robot.emulator.motors_running()
    assert list((tmp_path / "inbox").iterdir()) == []


def test_bump_front_and_rear(tmp_path):
    world = BoxWorld(pose=Pose2D(1.0, 0.0, 0.0))
    robot, _ = robot_on_emulator(tmp_path, world)
    with robot:
        r = robot.drive(2.0)
        assert r.status is MotionStatus.BUMPED and r.bumper == "front"
        assert world.truth_pose.x == pytest.approx(world.params.half_x_m - 0.12, abs=0.01)
        assert r.distance_m == pytest.approx(world.truth_pose.x - 1.0, abs=0.01)
        r = robot.turn(math.pi)  # touching the wall: turning in place is still possible
        assert r.status is MotionStatus.COMPLETED
        assert abs(r.angle_rad) == pytest.approx(math.pi, abs=0.03)
        r = robot.drive(-1.0)
        assert r.status is MotionStatus.BUMPED and r.bumper == "rear"
    assert not robot.emulator.motors_running()


class StuckWorld(BoxWorld):
    """Wheels blocked (e.g. a low obstacle the bumper misses): encoders stop."""

    stuck = False

    def step(self, dt):
        if self.stuck:
            self.t += dt
            return
        super().step(dt)


def test_stall_detected_from_rotation_counts(tmp_path):
    world = StuckWorld()
    robot, _ = robot_on_emulator(tmp_path, world)
    with robot:
        world.stuck = True
        r = robot.drive(0.5)
        assert r.status is MotionStatus.STALLED and abs(r.distance_m) < 0.01
        assert not robot.emulator.motors_running()


def _next(robot, k):
    return robot.emulator.command_count + k


def assert_photos_intact(emu, cap_dir: Path, expected: int) -> None:
    """Every photo the camera took arrived exactly once, complete, and the inbox is empty."""
    files = sorted(cap_dir.glob("*.jpg"))
    assert len(emu.photos) == expected == len(files)
    assert emu.uploads_pending == 0 and list(emu.inbox.iterdir()) == []
    data = [f.read_bytes() for f in files]
    assert all(d[:2] == b"\xff\xd8" and d[-2:] == b"\xff\xd9" for d in data)
    assert len(set(data)) == expected


def capture_with_fault(robot, cam, faults_list: list[int], cap_dir: Path, name: str) -> None:
    """Capture with a fault on the command that switches the camera port off (the 5th: the
    reboot check reads both wheel counters and the front bumper, then the port goes on)."""
    faults_list.append(_next(robot, 4))
    cam.capture(cap_dir / name)


def test_fault_dropped_replies(tmp_path):
    faults = FaultConfig()
    robot, cam = robot_on_emulator(tmp_path, faults=faults, reply_timeout_s=0.3)
    emu = robot.emulator
    with robot:
        n = _next(robot, 0)
        # n: GETOUTPUTSTATE (dropped) -> n+1 KEEPALIVE barrier -> n+2 retry; n+3 GETOUTPUTSTATE;
        # n+4 GETINPUTVALUES of the front bumper (the reboot check, after the counters);
        # n+5 / n+6: both wheels started back to back without replies; n+7: read-back of the
        # left wheel (dropped) -> n+8 barrier -> n+9 retry
        faults.drop_reply_at.extend([n, n + 7])
        r = robot.drive(0.3)
        gos1, ka = p.GetOutputState(port=1), p.KeepAlive()
        assert emu.commands[n : n + 5] == [gos1, ka, gos1, p.GetOutputState(port=2),
                                           p.GetInputValues(port=0)]  # fmt: skip
        starts = emu.commands[n + 5 : n + 7]
        assert all(isinstance(c, p.SetOutputState) and not c.reply for c in starts)
        assert emu.commands[n + 7 : n + 10] == [gos1, ka, gos1]
        assert r.status is MotionStatus.COMPLETED and r.distance_m == pytest.approx(0.3, abs=0.01)
        assert sum(c.tacho_limit > 0 for c in emu.commands if isinstance(c, p.SetOutputState)) == 2
        capture_with_fault(robot, cam, faults.drop_reply_at, tmp_path / "cap", "x.jpg")
        faults.drop_reply_prob = 0.15
        for i in range(3):
            cam.capture(tmp_path / "cap" / f"{i}.jpg")
            robot.turn(0.2)
        faults.drop_reply_prob = 0.0
    assert robot.client.stats.retries >= 2
    assert not emu.motors_running()
    assert_photos_intact(emu, tmp_path / "cap", 4)


def test_fault_lost_start_command_is_resent(tmp_path):
    faults = FaultConfig()
    world = BoxWorld()
    robot, _ = robot_on_emulator(tmp_path, world, faults=faults)
    emu = robot.emulator
    with robot:
        n = _next(robot, 0)
        faults.drop_command_at.append(n + 3)  # the left wheel's start never arrives
        r = robot.drive(0.3)
        assert isinstance(emu.commands[n + 3], p.SetOutputState)  # right wheel (n+3 was lost)
        resent = [c for c in emu.commands[n:] if isinstance(c, p.SetOutputState) and c.reply]
        assert resent[0].port == robot.left.port and resent[0].tacho_limit > 0
        assert r.status is MotionStatus.COMPLETED
        assert [f["fault"] for f in robot.drain_faults()] == ["motor_start_resent"]
        assert world.truth_pose.x == pytest.approx(0.3, abs=0.015)
    assert not emu.motors_running()


def test_fault_late_replies(tmp_path):
    faults = FaultConfig(late_reply_s=0.5)
    robot, cam = robot_on_emulator(tmp_path, faults=faults, reply_timeout_s=0.3)
    emu = robot.emulator
    with robot:
        n = _next(robot, 0)
        faults.late_reply_at.extend([n, n + 7])  # a query and the start read-back
        r = robot.drive(0.3)
        gos1, ka = p.GetOutputState(port=1), p.KeepAlive()
        assert emu.commands[n : n + 3] == [gos1, ka, gos1]
        assert emu.commands[n + 7 : n + 10] == [gos1, ka, gos1]
        assert r.status is MotionStatus.COMPLETED and r.distance_m == pytest.approx(0.3, abs=0.01)
        time.sleep(0.6)
        s = robot.sense()  # the late copies are drained, not taken as answers
        assert s.odometry.x == pytest.approx(0.3, abs=0.01)
        capture_with_fault(robot, cam, faults.late_reply_at, tmp_path / "cap", "a.jpg")
        cam.capture(tmp_path / "cap" / "b.jpg")
    assert_photos_intact(emu, tmp_path / "cap", 2)
    assert robot.client.stats.timeouts >= 2
    assert robot.client.stats.resyncs >= 2  # each timeout re-aligned with a KEEPALIVE barrier
    assert not emu.motors_running()


def test_fault_split_frames(tmp_path):
    robot, cam = robot_on_emulator(tmp_path, faults=FaultConfig(split_frames=True))
    with robot:
        assert robot.drive(0.2).status is MotionStatus.COMPLETED
        assert robot.sense().ultrasonic_cm > 0
        cam.capture(tmp_path / "cap" / "a.jpg")
    assert robot.client.stats.timeouts == 0
    assert_photos_intact(robot.emulator, tmp_path / "cap", 1)
    assert not robot.emulator.motors_running()


def test_fault_reboot_during_motion_and_idle(tmp_path):
    faults = FaultConfig()
    world = BoxWorld()
    robot, cam = robot_on_emulator(tmp_path, world, faults=faults)
    emu = robot.emulator
    with robot:
        faults.reboot_at.append(_next(robot, 12))  # mid-motion
        r = robot.drive(0.8)
        assert emu.reboots == 1 and robot.reboots == 1
        assert r.status is MotionStatus.LINK_LOST
        assert r.distance_m == pytest.approx(world.truth_pose.x, abs=0.02)
        faults.reboot_at.append(_next(robot, 0))  # while idle
        s = robot.sense()
        assert robot.reboots == 2
        assert s.odometry.x == pytest.approx(world.truth_pose.x, abs=0.02)
        x0 = world.truth_pose.x
        r = robot.drive(0.2)  # works again with the modes set anew
        assert r.status is MotionStatus.COMPLETED
        assert world.truth_pose.x - x0 == pytest.approx(0.2, abs=0.01)
        capture_with_fault(robot, cam, faults.reboot_at, tmp_path / "cap", "a.jpg")
        assert emu.reboots == 3
        assert robot.sense().ultrasonic_cm > 0  # modes restored after the third reboot
    assert not emu.motors_running()
    assert_photos_intact(emu, tmp_path / "cap", 1)


def test_fault_port_vanishes_and_returns(tmp_path):
    faults = FaultConfig(vanish_for_s=0.6)
    world = BoxWorld()
    robot, cam = robot_on_emulator(
        tmp_path, world, faults=faults, reconnect_delay_s=0.2, reconnect_attempts=10
    )
    emu = robot.emulator
    with robot:
        faults.vanish_at.append(_next(robot, 10))
        r = robot.drive(1.0)
        assert emu.vanished == 1 and robot.link_drops == 1
        assert r.status is MotionStatus.LINK_LOST
        assert not emu.motors_running()  # stopped first thing after the reconnect
        assert r.distance_m == pytest.approx(world.truth_pose.x, abs=0.03)
        assert robot.drive(0.1).status is MotionStatus.COMPLETED
        capture_with_fault(robot, cam, faults.vanish_at, tmp_path / "cap", "a.jpg")
        assert emu.vanished == 2 and robot.link_drops == 2
    assert not emu.motors_running()
    assert_photos_intact(emu, tmp_path / "cap", 1)


def test_fault_port_vanishes_for_good(tmp_path):
    faults = FaultConfig(vanish_for_s=None)
    with brick(tmp_path, faults=faults) as emu:  # the brick outlives the host's robot object
        cfg = NxtConfig(
            port=emu.port_path,
            camera={"inbox": str(tmp_path / "inbox")},
            reconnect_delay_s=0.05,
            reconnect_attempts=3,
            max_wheel_speed_deg_s=720.0,
        )
        robot, _ = make_nxt_robot(cfg, sigterm=False)
        faults.vanish_at.append(emu.command_count + 6)  # a status poll during the drive
        with pytest.raises(LinkLostError, match=r"could not reopen.*motors keep running"), robot:
            robot.drive(0.5)
        assert emu.vanished == 1
        # the link is gone, but every motion carries a tacho limit: the brick stops by itself
        deadline = time.monotonic() + 5.0
        while emu.motors_running() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not emu.motors_running()
        robot.close()  # idempotent, no error


def test_sleep_timer_keepalive_by_watchdog_thread(tmp_path):
    robot, _ = robot_on_emulator(tmp_path, emu={"sleep_limit_s": 0.8})
    with robot:
        time.sleep(1.6)  # idle: only the watchdog thread talks to the brick
        assert not robot.emulator.asleep
        assert robot.sense().ultrasonic_cm > 0
    assert robot.client.stats.keepalives >= 3


def test_sleep_timer_expires_without_keepalive(tmp_path):
    with brick(tmp_path, sleep_limit_s=0.5) as emu:
        client = connect(NxtConfig(port=emu.port_path, reconnect_attempts=0))
        client.output_state(1)  # motor commands and queries do not reset the timer
        time.sleep(0.8)
        assert emu.asleep
        with pytest.raises(LinkLostError):
            client.output_state(1)
        client.close()


def test_bad_port_busy_port_silent_brick_missing_inbox(tmp_path):
    with pytest.raises(PortNotFoundError, match=r"does not exist.*check nxt\.port"):
        connect(NxtConfig(port=str(tmp_path / "rfcomm9")))
    with brick(tmp_path) as emu:
        held = connect(NxtConfig(port=emu.port_path))
        with pytest.raises(PortBusyError, match=r"busy.*another program"):
            connect(NxtConfig(port=emu.port_path))
        with pytest.raises(CameraError, match=r"inbox folder .* does not exist"):
            NxtCamera(held, NxtConfig(camera={"inbox": str(tmp_path / "none")}).camera)
        held.close()
    master, slave = os.openpty()  # a port where nothing answers
    try:
        with pytest.raises(BrickNotAnsweringError, match=r"does not answer.*switched on"):
            connect(NxtConfig(port=os.ttyname(slave), reply_timeout_s=0.2, retries=0))
    finally:
        os.close(master)
        os.close(slave)
    with pytest.raises(FileNotFoundError, match="inbox"):
        NxtEmulator(BoxWorld(), EmulatorConfig(inbox=tmp_path / "missing"))


def test_unplugged_or_swapped_sensor_is_named(tmp_path):
    from scenebot.robot.base import RobotError

    cam = {"inbox": str(tmp_path / "inbox")}
    with brick(tmp_path) as emu:
        cfg = NxtConfig(port=emu.port_path, camera=cam, compass=4, ultrasonic=3)  # swapped
        with pytest.raises(RobotError, match=r"compass on sensor port 4 .* nxt\.compass"):
            make_nxt_robot(cfg, sigterm=False)
        del emu.devices[emu.us_port]  # ultrasonic unplugged
        with pytest.raises(RobotError, match=r"ultrasonic sensor on sensor port 4 does not"):
            make_nxt_robot(NxtConfig(port=emu.port_path, camera=cam), sigterm=False)
        assert not emu.motors_running()


def test_battery_low_refuses_to_start(tmp_path):
    from scenebot.robot.base import BatteryLowError

    with pytest.raises(BatteryLowError, match="6000 mV"):
        robot_on_emulator(tmp_path, emu={"battery_mv": 6000})


# ---------------------------------------------------------------------- safety


def test_exception_inside_motion_stops_motors(tmp_path):
    robot, _cam = robot_on_emulator(tmp_path)
    emu = robot.emulator

    def explode(*a):
        raise RuntimeError("bug in the control loop")

    with pytest.raises(RuntimeError, match="bug"), robot:
        robot._finished_status = explode  # fails while the wheels turn
        robot.odometry.update = explode
        robot.drive(2.0)
    assert not emu.motors_running()


def test_keyboard_interrupt_stops_motors_and_camera_port(tmp_path):
    robot, _cam = robot_on_emulator(tmp_path)
    emu = robot.emulator
    timer = threading.Timer(0.3, _thread.interrupt_main)
    # Python's own Ctrl-C handler: a process started in the background by a non-interactive
    # shell (nohup ... &) inherits SIGINT ignored, and interrupt_main() then does nothing
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt), robot:
            timer.start()
            robot.drive(5.0)
        timer.join()
    finally:
        signal.signal(signal.SIGINT, previous)
    assert not emu.motors_running()
    assert emu.motors[robot.camera_port].power == 0


def test_sigterm_stops_motors(tmp_path):
    robot, _cam = robot_on_emulator(tmp_path)
    emu = robot.emulator
    previous = signal.getsignal(signal.SIGTERM)
    try:
        assert install_sigterm_handler()
        timer = threading.Timer(0.3, os.kill, (os.getpid(), signal.SIGTERM))
        with pytest.raises(Terminated), robot:
            timer.start()
            robot.drive(5.0)
        timer.join()
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert not emu.motors_running()


def test_watchdog_interrupts_a_motion_whose_loop_hangs(tmp_path):
    robot, _ = robot_on_emulator(tmp_path, watchdog_timeout_s=0.3)
    emu = robot.emulator

    class HangOnce:  # the control loop stalls once for 1 s in the middle of a motion
        def __init__(self, clock):
            self.clock, self.hung = clock, False

        def monotonic(self):
            return self.clock.monotonic()

        def sleep(self, s):
            if not self.hung:
                self.hung = True
                time.sleep(1.0)
            self.clock.sleep(s)

    with robot:
        robot.clock = HangOnce(robot.clock)
        r = robot.drive(3.0)
        assert r.status is MotionStatus.STALLED and robot.watchdog_trips == 1
        assert r.distance_m < 1.0
    assert not emu.motors_running()


def test_watchdog_stops_motors_when_control_loop_stalls(tmp_path):
    robot, _ = robot_on_emulator(tmp_path, watchdog_timeout_s=0.3)
    emu = robot.emulator
    with robot:
        robot._heartbeat()
        robot._moving = True  # as inside a motion
        for port in (robot.left.port, robot.right.port):  # no tacho limit (no motion sends
            # this): only the watchdog can stop it
            robot.client.request(p.SetOutputState(port=port, power=40, mode=7, run_state=0x20))
        assert emu.motors_running()
        time.sleep(1.0)  # the control loop "hangs"
        assert not emu.motors_running()
        assert robot.watchdog_trips == 1
        robot._moving = False


def test_serve_prints_port_and_answers(tmp_path):
    from scenebot.robot.nxt.emulator import serve

    (tmp_path / "inbox").mkdir()
    lines: list[str] = []
    stop = threading.Event()
    world = BoxWorld()
    ecfg = EmulatorConfig(inbox=tmp_path / "inbox", time_scale=SCALE)
    th = threading.Thread(target=serve, args=(world, NxtConfig(), ecfg),
                          kwargs={"stop": stop, "print_fn": lines.append})  # fmt: skip
    th.start()
    try:
        deadline = time.monotonic() + 5.0
        while not lines and time.monotonic() < deadline:
            time.sleep(0.02)
        port = lines[0].split(" listening on ")[1].split(" ")[0]
        cfg = NxtConfig(port=port, camera={"inbox": str(tmp_path / "inbox")})
        robot, cam = make_nxt_robot(
            cfg.model_copy(update={"wheel_radius_m": 0.028, "wheel_base_m": 0.12,
                                   "max_wheel_speed_deg_s": 720.0}),
            sigterm=False,
        )  # fmt: skip
        with robot:
            assert robot.drive(0.2).status is MotionStatus.COMPLETED
            cam.capture(tmp_path / "a.jpg")
        assert world.truth_pose.x == pytest.approx(0.2, abs=0.01)
    finally:
        stop.set()
        th.join(timeout=5)
    assert not th.is_alive()
    assert not Path(port).exists()  # the pty link is removed on exit


def test_short_pulse_is_missed_like_chdk_and_times_out_cleanly(tmp_path):
    robot, cam = robot_on_emulator(
        tmp_path, emu={"camera_min_pulse_s": 0.3, "time_scale": 1.0},
        camera={"inbox": str(tmp_path / "inbox"), "pulse_s": 0.02, "timeout_s": 1.0},
    )  # fmt: skip
    emu = robot.emulator
    with robot:
        with pytest.raises(CameraError, match="no complete photo"):
            cam.capture(tmp_path / "cap" / "a.jpg")
        assert emu.photos == [] and not (tmp_path / "cap").exists()
        cam.cfg = cam.cfg.model_copy(update={"pulse_s": 0.5, "timeout_s": 10.0})
        cam.capture(tmp_path / "cap" / "b.jpg")  # a long enough pulse works
    assert_photos_intact(emu, tmp_path / "cap", 1)
    assert emu.motors[robot.camera_port].power == 0


# ---------------------------------------------------------------------- recovered faults


def _reboot_next(robot) -> None:
    """The brick reboots just before the next command it receives."""
    robot.emulator.cfg.faults.reboot_at.append(_next(robot, 0))


def _assert_odometry_matches_truth(robot, world) -> None:
    odo, truth = robot.sense().odometry, world.truth_pose
    assert odo.x == pytest.approx(truth.x, abs=0.015) and odo.y == pytest.approx(truth.y, abs=0.015)
    dth = math.atan2(math.sin(odo.theta - truth.theta), math.cos(odo.theta - truth.theta))
    assert abs(dth) < 0.03


@pytest.mark.parametrize("point", ["turn", "drive", "photo", "after_photo", "sense"])
def test_reboot_before_any_step_is_recovered_with_odometry_intact(tmp_path, point):
    """A brick reboot (counters reset, sensor modes lost) just before a turn, a drive, a photo
    trigger, right after a photo, or before a sensor read: every step checks for a reboot
    before it uses the wheel counters, so odometry continues from the last good pose, the
    step itself does what was asked, and the recovered fault is reported."""
    world = BoxWorld()
    robot, cam = robot_on_emulator(tmp_path, world)
    emu = robot.emulator
    with robot:
        assert robot.drive(0.3).status is MotionStatus.COMPLETED
        assert robot.turn(0.6).status is MotionStatus.COMPLETED
        robot.drain_faults()
        x0, th0 = world.truth_pose.x, world.truth_pose.theta
        if point == "turn":
            _reboot_next(robot)
            r = robot.turn(math.pi / 2)
            assert r.status is MotionStatus.COMPLETED
            assert r.angle_rad == pytest.approx(math.pi / 2, abs=0.03)
            assert world.truth_pose.theta - th0 == pytest.approx(math.pi / 2, abs=0.05)
        elif point == "drive":
            _reboot_next(robot)
            r = robot.drive(0.3)
            assert r.status is MotionStatus.COMPLETED
            assert r.distance_m == pytest.approx(0.3, abs=0.01)
            assert math.hypot(world.truth_pose.x - x0, world.truth_pose.y) > 0.25
        elif point == "photo":
            _reboot_next(robot)
            cam.capture(tmp_path / "cap" / "a.jpg")
            assert robot.turn(0.5).status is MotionStatus.COMPLETED
        elif point == "after_photo":  # the case: reboot after the trigger, then a turn
            trigger = cam.trigger

            def trigger_then_reboot():
                trigger()
                _reboot_next(robot)

            cam.trigger = trigger_then_reboot
            cam.capture(tmp_path / "cap" / "a.jpg")
            r = robot.turn(0.5)
            assert r.status is MotionStatus.COMPLETED
            assert r.angle_rad == pytest.approx(0.5, abs=0.03)
            assert world.truth_pose.theta - th0 == pytest.approx(0.5, abs=0.05)
        else:
            _reboot_next(robot)
            s = robot.sense()
            assert s.ultrasonic_cm > 0
        assert emu.reboots == 1 and robot.reboots == 1
        faults = robot.drain_faults()
        reboots = [f for f in faults if f["fault"] == "brick_reboot"]
        assert len(reboots) == 1 and reboots[0]["type"] == "fault" and reboots[0]["recovered"]
        assert reboots[0]["during"] == {"after_photo": "turn"}.get(point, point)
        _assert_odometry_matches_truth(robot, world)
        assert robot.drive(0.2).status is MotionStatus.COMPLETED  # sensors work again
        _assert_odometry_matches_truth(robot, world)
    assert not emu.motors_running()


def test_sensor_reads_and_motions_survive_drop_reply_prob(tmp_path):
    """One reply in ten lost, on every command: register reads are redone as transactions,
    reads retried, motor commands recovered as before."""
    faults = FaultConfig(drop_reply_prob=0.1, seed=3)
    world = BoxWorld()
    robot, cam = robot_on_emulator(tmp_path, world, faults=faults, reply_timeout_s=0.15)
    emu = robot.emulator
    with robot:
        for i in range(4):
            s = robot.sense()
            assert 0 < s.ultrasonic_cm <= 255 and 0.0 <= s.compass_deg < 360.0
            cam.capture(tmp_path / "cap" / f"{i}.jpg")
            assert robot.turn(0.4).status is MotionStatus.COMPLETED
        assert robot.drive(0.2).status is MotionStatus.COMPLETED
        _assert_odometry_matches_truth(robot, world)
        faults.drop_reply_prob = 0.0
        lost = [f for f in robot.drain_faults() if f["fault"] == "reply_lost"]
    assert robot.client.stats.timeouts >= 5 and lost
    assert not emu.motors_running()
    assert_photos_intact(emu, tmp_path / "cap", 4)


def test_slow_link_does_not_trip_the_watchdog(tmp_path):
    """Replies later than the watchdog timeout: the control loop is waiting on the link, not
    hung, so the watchdog lets the motion finish (the tacho limit bounds it anyway)."""
    faults = FaultConfig(late_reply_s=0.8)
    robot, _ = robot_on_emulator(tmp_path, faults=faults, watchdog_timeout_s=0.5)
    with robot:
        faults.late_reply_at.extend(_next(robot, k) for k in (8, 12))  # status polls
        r = robot.drive(0.4)
        assert r.status is MotionStatus.COMPLETED and robot.watchdog_trips == 0
    assert not robot.emulator.motors_running()


def test_every_wheel_command_is_tacho_limited(tmp_path):
    """A host killed mid-motion (SIGKILL) leaves the motors running until the limit: the worst
    case, because every command that powers a wheel carries a tacho limit."""
    from scenebot.robot.nxt.robot import run_command

    world = BoxWorld()
    robot, _ = robot_on_emulator(tmp_path, world)
    emu = robot.emulator
    with robot:
        robot.drive(0.3)
        robot.turn(-1.0)
        robot.turn_to_heading(90.0)
        robot.drive(-0.2)
    wheels = {robot.left.port, robot.right.port}
    powered = [
        c
        for c in emu.commands
        if isinstance(c, p.SetOutputState) and c.port in wheels and c.power != 0
    ]
    assert len(powered) >= 8 and all(c.tacho_limit > 0 for c in powered)
    with pytest.raises(ValueError, match="tacho limit"):
        run_command(1, 50, 0)


def test_emulator_that_fell_behind_drops_the_backlog(tmp_path):
    """After a slow render the physics catches up at most 200 steps, then drops the rest of
    the backlog: it must not keep running behind (and racing) from then on."""
    with brick(tmp_path) as emu, emu._lock:
        emu._wall0 -= 10.0  # as if the loop had stalled for 10 s
        emu._advance_physics()
        t1 = emu.world.t
        emu._advance_physics()
        assert emu.world.t - t1 < 0.1  # no backlog left: a few steps at most


def test_sensor_failure_is_a_clear_robot_error(tmp_path):
    from scenebot.robot.base import RobotError

    robot, _ = robot_on_emulator(tmp_path, reply_timeout_s=0.1, retries=0)
    with robot:
        robot.client.retries = 0
        robot.emulator.cfg.faults.drop_reply_prob = 1.0  # the brick goes silent
        with pytest.raises(RobotError, match=r"sensors.*check the Bluetooth link"):
            robot.sense()
        robot.emulator.cfg.faults.drop_reply_prob = 0.0
