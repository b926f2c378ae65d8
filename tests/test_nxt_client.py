"""Wire-level tests of the NXT client with a scripted transport and an injected clock."""

from __future__ import annotations

import threading

import pytest

from scenebot.robot.base import BatteryLowError, LinkLostError
from scenebot.robot.nxt import protocol as p
from scenebot.robot.nxt.client import BrickNotAnsweringError, NxtClient
from scenebot.robot.nxt.config import NxtConfig
from tests.fixtures.nxt_wire import FakeBrick, FakeClock


def brick_answer(telegram: bytes, battery=8100, sleep_ms=600000, status=0):
    """The reply a healthy brick sends (as a list for FakeBrick)."""
    cmd = p.parse_command(telegram)
    if not cmd.reply:
        return []
    if isinstance(cmd, p.KeepAlive):
        r = p.KeepAliveReply(sleep_limit_ms=sleep_ms).encode()
    elif isinstance(cmd, p.GetBatteryLevel):
        r = p.BatteryLevel(millivolts=battery).encode(status)
    elif isinstance(cmd, p.GetOutputState):
        r = p.OutputState(port=cmd.port, rotation_count=42).encode(status)
    elif isinstance(cmd, p.GetInputValues):
        r = p.InputValues(port=cmd.port, sensor_type=1, valid=True).encode(status)
    else:
        r = p.StatusReply(opcode=int(cmd.OPCODE)).encode(status)
    return [(0.0, p.frame(r))]


def make(respond=brick_answer, chunk=64, **kw):
    """A client with ``nxt`` settings ``kw`` (reply timeout 0.5 s, 2 retries, no automatic
    keepalive unless given)."""
    clock = FakeClock()
    brick = FakeBrick(clock, respond, chunk)
    kw = {"reply_timeout_s": 0.5, "retries": 2, "keepalive_interval_s": 1e9, **kw}
    client = NxtClient.from_config(brick, NxtConfig(**kw), clock=clock)
    client.last_keepalive = clock.t  # skip the automatic first keepalive unless tested
    return client, brick, clock


def test_request_exact_bytes_and_reply():
    client, brick, _ = make()
    st = client.output_state(2)
    assert brick.written == [bytes.fromhex("0300 00 06 02")]
    assert st.port == 2 and st.rotation_count == 42


def test_short_reads_are_assembled():
    client, brick, _ = make(chunk=1)
    assert client.battery_mv() == 8100
    assert brick.written == [bytes.fromhex("0200 00 0b")]


def test_timeout_retries_idempotent_then_raises():
    client, brick, clock = make(respond=lambda tg: [])
    t0 = clock.t
    with pytest.raises(p.ReplyTimeoutError, match="after 3 attempt"):
        client.output_state(1)
    ops = [w[3] for w in brick.written]
    # each failed attempt is followed by KEEPALIVE barriers (resync), also unanswered
    assert ops == [0x06, 0x0D, 0x0D] * 3
    assert clock.t - t0 >= 9 * 0.5  # waited on the injected clock, not the wall clock
    assert client.stats.timeouts == 9 and client.stats.retries == 2


def test_non_idempotent_command_is_not_retried():
    client, brick, _ = make(respond=lambda tg: [])
    cmd = p.SetOutputState(port=1, power=50, mode=7, regulation=1, run_state=0x20, tacho_limit=90)
    with pytest.raises(p.ReplyTimeoutError, match="unsafe to repeat"):
        client.request(cmd)
    assert brick.written[0] == cmd.packet()
    assert all(w == p.KeepAlive().packet() for w in brick.written[1:])


def test_late_reply_is_never_taken_for_a_later_request():
    calls = []

    def respond(tg):
        calls.append(tg)
        if len(calls) == 1:  # first reply arrives after the timeout
            return [(0.7, p.frame(p.OutputState(port=1, rotation_count=1).encode()))]
        if p.parse_command(tg) == p.KeepAlive():
            return brick_answer(tg)
        return [(0.001, p.frame(p.OutputState(port=1, rotation_count=2).encode()))]

    client, brick, _ = make(respond=respond)
    # timeout at 0.5 s -> KEEPALIVE barrier; the late reply (0.7 s) comes first and is
    # discarded, the barrier's reply follows, then the retry gets the fresh answer
    assert client.output_state(1).rotation_count == 2
    assert [w[3] for w in brick.written] == [0x06, 0x0D, 0x06]
    assert client.stats.stale_replies == 1 and client.stats.resyncs == 1


def test_reply_for_other_opcode_or_port_is_skipped():
    def respond(tg):
        cmd = p.parse_command(tg)
        stale = [
            (0.001, p.frame(p.StatusReply(opcode=4).encode())),
            (0.001, p.frame(p.OutputState(port=0, rotation_count=-1).encode())),
        ]
        fresh = p.OutputState(port=cmd.port, rotation_count=7).encode()
        return [*stale, (0.002, p.frame(fresh))]

    client, _, _ = make(respond=respond)
    assert client.output_state(2).rotation_count == 7
    assert client.stats.stale_replies == 2


def test_status_error_is_typed_and_not_retried():
    client, brick, _ = make(respond=lambda tg: brick_answer(tg, status=0xC0))
    with pytest.raises(p.OutOfRangeError):
        client.output_state(5)
    assert len(brick.written) == 1


def test_malformed_reply_retried_for_idempotent():
    n = []

    def respond(tg):
        n.append(1)
        if len(n) == 1:
            return [(0.001, p.frame(bytes.fromhex("02 0b 00 a4")))]  # one byte short
        return brick_answer(tg)

    client, brick, _ = make(respond=respond)
    assert client.battery_mv() == 8100
    assert [w[3] for w in brick.written] == [0x0B, 0x0D, 0x0B] and client.stats.malformed == 1


def test_bad_length_prefix_is_a_framing_error_then_retry():
    n = []

    def respond(tg):
        n.append(1)
        return [(0.001, b"\x00\x00")] if len(n) == 1 else brick_answer(tg)

    client, _, _ = make(respond=respond)
    assert client.battery_mv() == 8100


def test_no_reply_command_writes_type_0x80_and_returns_none():
    client, brick, _ = make()
    assert client.request(p.KeepAlive(reply=False)) is None
    assert brick.written == [bytes.fromhex("0200 80 0d")]


def test_keepalive_schedule_uses_sleep_limit_and_ignores_motor_commands():
    client, brick, clock = make(
        respond=lambda tg: brick_answer(tg, sleep_ms=10_000), keepalive_interval_s=60.0
    )
    client.last_keepalive = None
    client.output_state(1)  # first request: KEEPALIVE goes first
    assert [w[3] for w in brick.written] == [0x0D, 0x06]
    assert client.sleep_limit_ms == 10_000
    for _ in range(4):  # motor commands for 4.8 s: no keepalive yet (< half of 10 s)
        clock.sleep(1.2)
        client.request(p.SetOutputState(port=1, power=10, mode=1, run_state=0x20))
    assert sum(w[3] == 0x0D for w in brick.written) == 1
    clock.sleep(0.3)  # 5.1 s since the last KEEPALIVE: due before the next command
    client.request(p.SetOutputState(port=1))
    assert [w[3] for w in brick.written[-2:]] == [0x0D, 0x04]


def test_battery_check():
    client, _, _ = make(respond=lambda tg: brick_answer(tg, battery=5900))
    with pytest.raises(BatteryLowError, match="battery_min_mv = 6300"):
        client.check_battery(6300)
    assert client.check_battery(5000) == 5900


def test_handshake_clear_error_when_brick_silent():
    client, _, _ = make(respond=lambda tg: [], port="/dev/rfcomm7")
    with pytest.raises(BrickNotAnsweringError, match=r"/dev/rfcomm7: is it switched on"):
        client.handshake()


def test_reconnect_runs_hooks_then_retries_idempotent():
    clock = FakeClock()
    first = FakeBrick(clock, brick_answer)
    first.fail_read = OSError(5, "read failed: EIO")
    second = FakeBrick(clock, brick_answer)
    hooks = []
    cfg = NxtConfig(
        reply_timeout_s=0.5, keepalive_interval_s=1e9, reconnect_attempts=3, reconnect_delay_s=0.2
    )
    client = NxtClient.from_config(first, cfg, clock=clock, opener=lambda: second)
    client.last_keepalive = clock.t
    client.on_reconnect.append(lambda: hooks.append(client.keepalive()))
    assert client.output_state(1).rotation_count == 42
    assert first.closed and hooks == [600000] and client.stats.reconnects == 1
    assert [w[3] for w in second.written] == [0x0D, 0x06]


def test_reconnect_failure_is_link_lost():
    clock = FakeClock()
    first = FakeBrick(clock, brick_answer)
    first.fail_read = OSError(5, "EIO")

    def opener():
        raise FileNotFoundError(2, "No such file")

    client = NxtClient.from_config(
        first, NxtConfig(reconnect_attempts=2), clock=clock, opener=opener
    )
    client.last_keepalive = clock.t
    with pytest.raises(LinkLostError, match="motors keep running"):
        client.battery_mv()


def test_one_request_in_flight_across_threads():
    client, brick, _ = make(chunk=1)
    errors = []

    def worker(port):
        try:
            for _ in range(30):
                assert client.output_state(port).port == port
        except Exception as exc:  # pragma: no cover - reported below
            errors.append(exc)

    threads = [threading.Thread(target=worker, args=(i,)) for i in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors and not brick.overlap and len(brick.written) == 90


def test_after_a_failed_reopen_requests_fail_fast():
    clock = FakeClock()
    first = FakeBrick(clock, brick_answer)
    first.fail_read = OSError(5, "EIO")
    opened = []

    def opener():
        opened.append(1)
        raise FileNotFoundError(2, "No such file")

    client = NxtClient.from_config(
        first, NxtConfig(reconnect_attempts=2), clock=clock, opener=opener
    )
    client.last_keepalive = clock.t
    with pytest.raises(LinkLostError):
        client.battery_mv()
    t = clock.t
    with pytest.raises(LinkLostError, match="is lost"):
        client.output_state(0)
    assert len(opened) == 2 and clock.t == t  # no new reopen attempts, no waiting


# ------------------------------------------------------------------ adaptive timeouts, lost replies


def test_rtt_estimator_floor_ewma_backoff_and_cap():
    from scenebot.robot.nxt.client import RttEstimator

    est = RttEstimator(floor_s=0.5, cap_s=4.0)
    assert est.timeout_s == 0.5  # before any sample: the configured timeout
    for _ in range(20):
        est.sample(0.002)
    assert est.timeout_s == 0.5  # a fast link never goes below the configured timeout
    est.sample(0.6)  # one slow round trip: srtt + 4 rttvar grows past it at once
    assert est.timeout_s > 0.6
    for _ in range(60):
        est.sample(0.6)
    assert 0.6 < est.timeout_s < 0.7  # a steady 0.6 s link: srtt ~ 0.6, rttvar ~ 0
    est.backoff()
    assert est.timeout_s == pytest.approx(2 * 0.6, rel=0.1)
    for _ in range(5):
        est.backoff()
    assert est.timeout_s == 4.0  # capped
    est.sample(0.6)  # a measured round trip replaces the backed-off value
    assert est.timeout_s < 1.0


def test_reply_timeout_adapts_to_a_slow_link():
    """A loaded machine: every reply takes 0.6 s, longer than the configured 0.5 s. After the
    first timeout the client measures the round trip and stops timing out, so even commands
    that are unsafe to repeat (LSWRITE) go through."""

    def slow(tg):
        return [(delay + 0.6, out) for delay, out in brick_answer(tg)]

    client, _, _ = make(respond=slow)
    client.keepalive()  # safe to repeat: survives the first timeout
    for _ in range(10):
        client.request(p.LsWrite(port=3, tx=b"\x02\x42", rx_len=1))
    assert client.stats.timeouts == 1
    assert client.reply_timeout_now_s > 0.6


def test_idempotent_read_retried_while_the_brick_answers():
    """Replies lost on a live link (the KEEPALIVE barriers are answered) do not use up the
    retries meant for a silent brick; every recovered loss is reported as a fault event."""
    lost = []

    def respond(tg):
        if p.parse_command(tg) == p.GetOutputState(port=1) and len(lost) < 4:
            lost.append(tg)
            return []
        return brick_answer(tg)

    client, brick, _ = make(respond=respond)
    assert client.output_state(1).rotation_count == 42  # 5th attempt, retries=2
    assert [w[3] for w in brick.written] == [0x06, 0x0D] * 4 + [0x06]
    events = client.drain_faults()
    assert len(events) == 1 and events[0]["type"] == "fault"
    assert events[0]["fault"] == "reply_lost" and events[0]["command"] == "GetOutputState"
    assert events[0]["attempts"] == 5 and events[0]["recovered"] is True
    assert client.drain_faults() == []
