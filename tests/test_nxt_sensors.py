"""NXT sensors at the wire level (scripted brick, injected clock) and odometry / stall maths."""

from __future__ import annotations

import math

import pytest

from scenebot.robot.base import Pose2D
from scenebot.robot.nxt import protocol as p
from scenebot.robot.nxt.client import NxtClient
from scenebot.robot.nxt.config import NxtConfig
from scenebot.robot.nxt.sensors import (
    HiTechnicCompass,
    Odometry,
    SensorModeLost,
    SensorReadError,
    StallDetector,
    TouchSensor,
    Ultrasonic,
    compass_to_ccw,
)
from tests.fixtures.nxt_wire import FakeBrick, FakeClock

NXT = NxtConfig()


class I2CBrick:
    """Scripted brick for one I2C port: busy for ``busy`` LSWRITEs, pending for ``pending``
    LSGETSTATUS polls, then registers from ``regs``; ``bus_errors`` failed transactions."""

    def __init__(self, regs, sensor_type=0x0B, busy=0, pending=0, bus_errors=0, lose=None):
        self.regs, self.sensor_type = dict(regs), sensor_type
        self.busy, self.pending, self.bus_errors = busy, pending, bus_errors
        self.lose = dict(lose or {})  # command class -> replies to lose (command executed)
        self.rx = b""
        self.log: list[p.Command] = []

    def __call__(self, telegram):
        cmd = p.parse_command(telegram)
        self.log.append(cmd)
        lost = self.lose.get(type(cmd), 0) > 0
        if lost:
            self.lose[type(cmd)] -= 1

        def out(reply, status=0):
            return [] if lost else [(0.0, p.frame(reply.encode(status)))]

        if isinstance(cmd, p.KeepAlive):
            return out(p.KeepAliveReply(sleep_limit_ms=600000))

        if isinstance(cmd, p.SetInputMode):
            return out(p.StatusReply(opcode=5))
        if isinstance(cmd, p.GetInputValues):
            return out(p.InputValues(port=cmd.port, sensor_type=self.sensor_type, valid=True))
        if isinstance(cmd, p.LsWrite):
            if self.busy:
                self.busy -= 1
                return out(p.StatusReply(opcode=0x0F), 0xE0)
            reg = cmd.tx[1]
            for i, b in enumerate(cmd.tx[2:]):
                self.regs[reg + i] = b
            self.rx = bytes(self.regs.get(r, 0) for r in range(reg, reg + cmd.rx_len))
            return out(p.StatusReply(opcode=0x0F))
        if isinstance(cmd, p.LsGetStatus):
            if self.pending:
                self.pending -= 1
                return out(p.LsStatus(), 0x20)
            if self.bus_errors:
                self.bus_errors -= 1
                return out(p.LsStatus(), 0xDD)
            return out(p.LsStatus(bytes_ready=len(self.rx)))
        if isinstance(cmd, p.LsRead):
            data, self.rx = self.rx, b""
            return out(p.LsReadReply(data=data))
        raise AssertionError(cmd)


def client_for(brick):
    clock = FakeClock()
    c = NxtClient.from_config(
        FakeBrick(clock, brick), NxtConfig(keepalive_interval_s=1e9), clock=clock
    )
    c.last_keepalive = clock.t
    return c, clock


def test_ultrasonic_setup_and_read_exact_sequence():
    brick = I2CBrick({0x42: 87}, busy=2, pending=1)
    c, clock = client_for(brick)
    us = Ultrasonic(c, 3, clock)
    us.setup()
    assert brick.regs[0x41] == 0x02  # continuous measurement
    assert us.distance_cm() == 87
    packets = c.transport.written
    assert packets[0] == bytes.fromhex("0500 00 05 03 0b 00")  # LOWSPEED_9V, raw
    assert packets[1] == packets[2] == packets[3] == bytes.fromhex("0800 00 0f 03 03 00 02 41 02")
    assert bytes.fromhex("0700 00 0f 03 02 01 02 42") in packets
    assert packets[-1] == bytes.fromhex("0300 00 10 03")


def test_ultrasonic_no_echo_is_255():
    c, clock = client_for(I2CBrick({0x42: 255}))
    assert Ultrasonic(c, 0, clock).distance_cm() == 255


@pytest.mark.parametrize(("h", "ccw"), [(0, 0.0), (90, 270.0), (359, 1.0), (181, 179.0)])
def test_compass_registers_and_clockwise_conversion(h, ccw):
    c, clock = client_for(I2CBrick({0x42: h // 2, 0x43: h % 2}, sensor_type=0x0A))
    cw = HiTechnicCompass(c, 2, clock, "clockwise", offset_deg=0.0)
    assert cw.raw_heading_deg() == h
    assert cw.heading_ccw_deg() == pytest.approx(ccw)
    same = HiTechnicCompass(c, 2, clock, "counter_clockwise", offset_deg=10.0)
    assert same.heading_ccw_deg() == pytest.approx((h + 10.0) % 360.0)


def test_compass_impossible_registers():
    c, clock = client_for(I2CBrick({0x42: 200, 0x43: 0}, sensor_type=0x0A))
    with pytest.raises(SensorReadError, match="HiTechnic"):
        HiTechnicCompass(
            c, 2, clock, NXT.compass_convention, NXT.compass_offset_deg
        ).raw_heading_deg()


def test_compass_to_ccw_bad_convention():
    assert compass_to_ccw(10.0, "clockwise", 0.0) == 350.0
    with pytest.raises(ValueError, match="convention"):
        compass_to_ccw(10.0, "north", 0.0)


def test_bus_error_retries_whole_transaction():
    brick = I2CBrick({0x42: 33}, bus_errors=2)
    c, clock = client_for(brick)
    assert Ultrasonic(c, 1, clock).distance_cm() == 33
    assert sum(isinstance(cmd, p.LsWrite) for cmd in brick.log) == 3
    brick2 = I2CBrick({0x42: 33}, bus_errors=5)
    c2, clock2 = client_for(brick2)
    with pytest.raises(p.BusError):
        Ultrasonic(c2, 1, clock2).distance_cm()


def test_lost_mode_after_reboot_raises_sensor_mode_lost():
    brick = I2CBrick({0x42: 1}, sensor_type=0x00, busy=10_000)  # port reset to NO_SENSOR
    c, clock = client_for(brick)
    with pytest.raises(SensorModeLost, match="ultrasonic"):
        Ultrasonic(c, 3, clock).distance_cm()


def test_touch_sensor_boolean_and_mode_check():
    state = {"type": 1, "scaled": 1}

    def brick(tg):
        cmd = p.parse_command(tg)
        if isinstance(cmd, p.SetInputMode):
            return [(0.0, p.frame(p.StatusReply(opcode=5).encode()))]
        r = p.InputValues(
            port=cmd.port,
            valid=True,
            sensor_type=state["type"],
            sensor_mode=0x20,
            scaled=state["scaled"],
        )
        return [(0.0, p.frame(r.encode()))]

    c, _ = client_for(brick)
    t = TouchSensor(c, 0, "front bumper")
    t.setup()
    assert c.transport.written[0] == bytes.fromhex("0500 00 05 00 01 20")
    assert t.pressed()
    state["scaled"] = 0
    assert not t.pressed()
    state["type"] = 0
    with pytest.raises(SensorModeLost, match="front bumper on sensor port 1"):
        t.pressed()


def test_odometry_straight_and_turn():
    r, b = 0.03, 0.12
    odo = Odometry(r, b, Pose2D(0.0, 0.0, math.pi / 2))
    odo.update(0.0, 0.0)
    deg = math.degrees(0.5 / r)
    ds, dth = odo.update(deg, deg)
    assert ds == pytest.approx(0.5) and dth == pytest.approx(0.0)
    assert odo.pose.x == pytest.approx(0.0, abs=1e-12) and odo.pose.y == pytest.approx(0.5)
    turn = math.degrees((math.pi / 2) * (b / 2) / r)  # +90 deg counter-clockwise in place
    odo.update(deg - turn, deg + turn)
    assert odo.pose.theta == pytest.approx(math.pi)
    assert odo.pose.y == pytest.approx(0.5)
    odo.rebaseline(0.0, 0.0)  # counters reset (reboot): pose unchanged
    odo.update(10.0, 10.0)
    assert odo.pose.x == pytest.approx(-math.radians(10.0) * r)


def test_odometry_arc_matches_circle():
    r, b = 0.028, 0.12
    odo = Odometry(r, b, Pose2D(0.0, 0.0, 0.0))
    odo.update(0.0, 0.0)
    # right wheel twice as fast: radius of curvature R = b/2 * (vr+vl)/(vr-vl) = 3b/2
    L = R = 1.5 * b
    for k in range(1, 201):
        phi = math.pi * k / 200  # half circle
        sl = (R - b / 2) * phi
        sr = (R + b / 2) * phi
        odo.update(math.degrees(sl / r), math.degrees(sr / r))
    assert odo.pose.x == pytest.approx(0.0, abs=1e-3)
    assert odo.pose.y == pytest.approx(2 * L, abs=1e-3)
    assert odo.pose.theta == pytest.approx(math.pi, abs=1e-9)


def test_stall_detector():
    s = StallDetector(window_s=0.5, min_deg=4.0)
    t, c = 0.0, 0.0
    for _ in range(20):  # moving 10 deg per 0.05 s
        t += 0.05
        c += 10.0
        assert not s.update(t, c)
    stalled_at = None
    for _ in range(20):  # blocked
        t += 0.05
        c += 0.1
        if s.update(t, c):
            stalled_at = t
            break
    assert stalled_at is not None and 1.0 + 0.45 <= stalled_at <= 1.0 + 0.6
    s.reset()
    assert not s.update(t + 0.05, c)


@pytest.mark.parametrize(
    ("lose", "writes"),
    [({p.LsWrite: 1}, 2), ({p.LsRead: 1}, 2), ({p.LsWrite: 2, p.LsRead: 3}, 6)],
)
def test_lost_reply_redoes_the_whole_register_read(lose, writes):
    """LSWRITE and LSREAD are unsafe to repeat on their own, but a register read is a
    transaction that can be redone from the start (write, poll, read)."""
    brick = I2CBrick({0x42: 87}, lose=lose)
    c, clock = client_for(brick)
    assert Ultrasonic(c, 3, clock).distance_cm() == 87
    assert sum(isinstance(cmd, p.LsWrite) for cmd in brick.log) == writes
    events = [e for e in c.drain_faults() if e.get("sensor") == "ultrasonic sensor"]
    assert len(events) == 1 and events[0]["recovered"] and events[0]["attempts"] == writes


def test_lost_reply_redoes_a_register_write():
    brick = I2CBrick({}, sensor_type=0x0A, lose={p.LsWrite: 1})
    c, clock = client_for(brick)
    HiTechnicCompass(c, 2, clock, NXT.compass_convention, NXT.compass_offset_deg).setup()
    assert brick.regs[0x41] == 0x00
    assert sum(isinstance(cmd, p.LsWrite) for cmd in brick.log) == 2


def test_register_read_gives_up_when_the_brick_falls_silent():
    brick = I2CBrick({0x42: 87}, lose={p.LsWrite: 1, p.KeepAlive: 10**6, p.LsGetStatus: 10**6})
    c, clock = client_for(brick)
    with pytest.raises(p.ReplyTimeoutError, match="ultrasonic sensor on sensor port 4"):
        Ultrasonic(c, 3, clock).distance_cm()
    assert sum(isinstance(cmd, p.LsWrite) for cmd in brick.log) <= 1 + c.retries


def test_transaction_stuck_pending_is_redone_from_the_start():
    """A transfer still pending after ``pending_timeout_s`` (the mode is intact) is a failed
    attempt of a transaction that can be redone, not the end of the capture."""
    brick = I2CBrick({0x42: 87}, pending=80)  # > pending_timeout_s of 5 ms polls
    c, clock = client_for(brick)
    assert Ultrasonic(c, 3, clock).distance_cm() == 87
    assert sum(isinstance(cmd, p.LsWrite) for cmd in brick.log) == 2
