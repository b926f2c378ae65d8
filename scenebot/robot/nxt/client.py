"""NXT direct-command client over a pyserial-like transport.

One request is in flight at a time (a re-entrant lock serialises the control loop and the
watchdog thread). Every reply is validated (type, opcode echo, port echo, status, length).
Commands that are safe to repeat (:attr:`Command.idempotent`) are retried after a timeout, a
malformed reply or a reconnect; the others raise :class:`ReplyTimeoutError` so the caller can
find out what happened (e.g. by reading the motor state) or redo a whole transaction (an I2C
register read) instead of repeating one command of it.

A lost reply on a live link (the brick answers the KEEPALIVE barrier that follows) and a
silent brick are told apart: ``retries`` bounds the attempts in which the brick did not answer
at all; while it keeps answering, a safe command is tried up to ``LIVE_RETRY_FACTOR`` times as
often (a Bluetooth link that loses one reply in ten must not end a capture). Every request
that needed more than one attempt is reported as a fault event (:meth:`NxtClient.drain_faults`)
for the capture log.

The reply timeout adapts to the measured round-trip time (:class:`RttEstimator`, as TCP does):
never below the configured ``reply_timeout_s``, longer on a slow or loaded link, doubled after
each timeout until a new round trip is measured.

The brick's sleep timer is reset only by KEEPALIVE (motor commands do not reset it), so the
client sends one whenever the last is older than ``keepalive_interval_s`` or half the sleep
limit the brick reported, before any other request.

After a timeout or a garbled reply the client re-aligns the streams with a KEEPALIVE barrier
(the brick answers in order; everything before the barrier's reply is stale), so a late reply
is never taken for the answer to a later request.

Time comes from an injected :class:`Clock`, so wire-level tests run without sleeping.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol

from scenebot.robot.base import BatteryLowError, LinkLostError, RobotError
from scenebot.robot.nxt.protocol import (
    REPLY,
    Command,
    FramingError,
    GetBatteryLevel,
    GetInputValues,
    GetOutputState,
    InputValues,
    KeepAlive,
    MalformedReplyError,
    OutputState,
    ProtocolError,
    Reply,
    ReplyTimeoutError,
    parse_reply,
)

if TYPE_CHECKING:
    from scenebot.robot.nxt.config import NxtConfig

log = logging.getLogger(__name__)

READ_SLICE_S = 0.05
"""Transport read timeout (s): the client loops over short reads until its own deadline."""

RTT_ALPHA = 1.0 / 8.0
"""Weight of a new round trip in the smoothed round-trip time (RFC 6298)."""
RTT_BETA = 1.0 / 4.0
"""Weight of a new deviation in the round-trip variation (RFC 6298)."""
RTT_K = 4.0
"""The timeout is the smoothed round trip plus this many deviations (RFC 6298)."""
MAX_TIMEOUT_FACTOR = 8.0
"""The adaptive reply timeout never exceeds this multiple of the configured one."""
LIVE_RETRY_FACTOR = 4
"""While the brick answers, a safe command gets this many times ``1 + retries`` attempts."""
FAULT_EVENTS_MAX = 10_000
"""Recovered-fault events kept until drained (the oldest are dropped beyond this)."""


class RttEstimator:
    """Reply timeout from measured round trips: smoothed RTT plus ``RTT_K`` deviations.

    The estimate follows RFC 6298 (Jacobson/Karels): ``srtt`` and ``rttvar`` are exponentially
    weighted moving averages of the round trip and of its deviation; the timeout is
    ``srtt + max(READ_SLICE_S, RTT_K * rttvar)`` (the read slice is the clock granularity),
    clamped to ``[floor_s, cap_s]``. A timeout doubles it (backoff) until the next sample.

    Args:
        floor_s: the configured reply timeout (s): the timeout never goes below it.
        cap_s: the largest timeout (s).
    """

    def __init__(self, floor_s: float, cap_s: float):
        self.floor_s, self.cap_s = floor_s, max(cap_s, floor_s)
        self.srtt_s: float | None = None
        self.rttvar_s: float | None = None
        self.timeout_s = floor_s

    def sample(self, rtt_s: float) -> None:
        """Add one measured round trip (s) of an unambiguous exchange."""
        if self.srtt_s is None or self.rttvar_s is None:
            self.srtt_s, self.rttvar_s = rtt_s, rtt_s / 2.0
        else:
            self.rttvar_s = (1.0 - RTT_BETA) * self.rttvar_s + RTT_BETA * abs(self.srtt_s - rtt_s)
            self.srtt_s = (1.0 - RTT_ALPHA) * self.srtt_s + RTT_ALPHA * rtt_s
        rto = self.srtt_s + max(READ_SLICE_S, RTT_K * self.rttvar_s)
        self.timeout_s = min(self.cap_s, max(self.floor_s, rto))

    def backoff(self) -> None:
        """A reply timed out: wait twice as long until a round trip is measured again."""
        self.timeout_s = min(self.cap_s, 2.0 * self.timeout_s)


class RetryBudget:
    """How many failed attempts of one request (or transaction) may be followed by another.

    At most ``1 + retries`` attempts in which the brick did not answer at all (a silent brick
    fails as fast as before), and ``LIVE_RETRY_FACTOR * (1 + retries)`` attempts in all while it
    answers the KEEPALIVE barriers (only replies are being lost).
    """

    def __init__(self, retries: int):
        self.retries = retries
        self.attempts = 0
        self.silent = 0

    def spend(self, brick_answered: bool) -> bool:
        """Count one failed attempt; return whether another attempt is allowed."""
        self.attempts += 1
        if not brick_answered:
            self.silent += 1
        allowed = LIVE_RETRY_FACTOR * (1 + self.retries)
        return self.silent <= self.retries and self.attempts < allowed


class Clock(Protocol):
    """Time source: seconds from an arbitrary origin, and a way to wait."""

    def monotonic(self) -> float: ...

    def sleep(self, seconds: float) -> None: ...


class SystemClock:
    """The real clock."""

    def monotonic(self) -> float:
        return time.monotonic()

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds)


class Transport(Protocol):
    """The subset of :class:`serial.Serial` the client uses."""

    def write(self, data: bytes) -> int | None: ...

    def read(self, size: int = 1) -> bytes: ...

    @property
    def in_waiting(self) -> int: ...

    def reset_input_buffer(self) -> None: ...

    def close(self) -> None: ...


class PortNotFoundError(RobotError):
    """The configured serial port does not exist."""


class PortBusyError(RobotError):
    """Another program holds the serial port."""


class BrickNotAnsweringError(LinkLostError):
    """The port opened but the brick does not answer."""


def open_serial(port: str, baudrate: int, timeout_s: float = READ_SLICE_S) -> Transport:
    """Open ``port`` at ``baudrate`` (``nxt.baudrate``) with pyserial (exclusive lock),
    translating failures into clear errors.

    Raises:
        PortNotFoundError: no such device.
        PortBusyError: another process has the port open (or holds its lock).
        RobotError: other failures (permissions, Bluetooth link refused), with what to check.
    """
    import serial

    try:
        return serial.Serial(
            port, baudrate=baudrate, timeout=timeout_s, write_timeout=2.0, exclusive=True
        )
    except (serial.SerialException, OSError) as exc:
        code = getattr(exc, "errno", None)
        text = str(exc)
        if code == errno.ENOENT or "No such file" in text:
            raise PortNotFoundError(
                f"serial port {port} does not exist: check nxt.port in the config; for a "
                "real brick pair it (bluetoothctl pair <MAC>) and bind it (sudo rfcomm bind 0 "
                "<MAC> 1) so /dev/rfcomm0 appears; for the emulator use the path that "
                "`scenebot nxt-emulator` printed"
            ) from exc
        if code in (errno.EBUSY, errno.EAGAIN, errno.EWOULDBLOCK) or "lock" in text.lower():
            raise PortBusyError(
                f"serial port {port} is busy: another program has it open (another scenebot "
                "run, nxt-python, a terminal program such as minicom); close it and retry"
            ) from exc
        if code == errno.EACCES:
            raise RobotError(
                f"no permission to open {port}: add your user to the 'dialout' group "
                "(sudo usermod -aG dialout $USER, then log in again)"
            ) from exc
        if code in (errno.EHOSTDOWN, errno.ECONNREFUSED, errno.EHOSTUNREACH, errno.ETIMEDOUT):
            raise BrickNotAnsweringError(
                f"Bluetooth link to the brick on {port} failed ({exc}): is the brick switched "
                "on, in range, with Bluetooth enabled and paired with this computer?"
            ) from exc
        raise RobotError(f"cannot open serial port {port}: {exc}") from exc


@dataclass
class ClientStats:
    """Counters for diagnostics and tests."""

    requests: int = 0
    retries: int = 0
    timeouts: int = 0
    stale_replies: int = 0
    resyncs: int = 0
    malformed: int = 0
    reconnects: int = 0
    keepalives: int = 0
    bytes_flushed: int = 0
    opcodes: deque[int] = field(default_factory=lambda: deque(maxlen=256))


class NxtClient:
    """Talk to one NXT brick.

    The link settings are ``nxt``'s (:class:`~scenebot.robot.nxt.config.NxtConfig`);
    :meth:`from_config` passes them.

    Args:
        transport: an open pyserial-like port (read timeout small, e.g. 50 ms).
        clock: time source (default: the real clock).
        reply_timeout_s: time to wait for a complete reply.
        retries: extra attempts for idempotent commands.
        keepalive_interval_s: send KEEPALIVE at least this often.
        opener: callable that reopens the port after a link failure (None: no reconnect).
        reconnect_attempts: times to call ``opener``.
        reconnect_delay_s: pause between reconnect attempts.
        port_name: the port path, for messages.
    """

    def __init__(
        self,
        transport: Transport,
        *,
        clock: Clock | None = None,
        reply_timeout_s: float,
        retries: int,
        keepalive_interval_s: float,
        opener: Callable[[], Transport] | None = None,
        reconnect_attempts: int,
        reconnect_delay_s: float,
        port_name: str = "the NXT port",
    ):
        self.transport: Transport | None = transport
        self.clock: Clock = clock or SystemClock()
        self.reply_timeout_s = reply_timeout_s
        self.retries = retries
        self.keepalive_interval_s = keepalive_interval_s
        self.opener = opener
        self.reconnect_attempts = reconnect_attempts
        self.reconnect_delay_s = reconnect_delay_s
        self.port_name = port_name
        self.lock = threading.RLock()
        self.stats = ClientStats()
        self.sleep_limit_ms: int | None = None
        self.last_keepalive: float | None = None
        self.last_battery_mv: int | None = None
        self.on_reconnect: list[Callable[[], None]] = []
        self.on_activity: list[Callable[[], None]] = []  # a request started/ended, a reply came
        self.fault_events: deque[dict] = deque(maxlen=FAULT_EVENTS_MAX)
        self.rtt = RttEstimator(reply_timeout_s, MAX_TIMEOUT_FACTOR * reply_timeout_s)
        self._in_reconnect = False
        self.closed = False
        self.link_dead: str | None = None  # set when reopening the port failed for good

    @classmethod
    def from_config(
        cls,
        transport: Transport,
        cfg: NxtConfig,
        *,
        clock: Clock | None = None,
        opener: Callable[[], Transport] | None = None,
    ) -> NxtClient:
        """A client on ``transport`` with ``cfg``'s link settings (reply timeout, retries,
        keepalive, reconnects; ``cfg.port`` names the port in messages)."""
        return cls(
            transport,
            clock=clock,
            reply_timeout_s=cfg.reply_timeout_s,
            retries=cfg.retries,
            keepalive_interval_s=cfg.keepalive_interval_s,
            opener=opener,
            reconnect_attempts=cfg.reconnect_attempts,
            reconnect_delay_s=cfg.reconnect_delay_s,
            port_name=cfg.port,
        )

    # ------------------------------------------------------------------ public API

    def request(self, cmd: Command) -> Reply | None:
        """Send ``cmd``; return its validated reply (``None`` for no-reply commands).

        Raises:
            DirectCommandError: the brick reported an error status (not retried).
            ReplyTimeoutError: no valid reply for a command that is unsafe to repeat (it may
                or may not have executed), or none after all retries.
            LinkLostError: the port failed and could not be reopened.
        """
        with self.lock:
            if self.closed:
                raise LinkLostError(f"NXT client on {self.port_name} is closed")
            if self.link_dead is not None:
                raise LinkLostError(
                    f"the link to the NXT on {self.port_name} is lost ({self.link_dead})"
                )
            self._activity()
            try:
                if not isinstance(cmd, KeepAlive):
                    self.maybe_keepalive()
                return self._request(cmd)
            finally:
                self._activity()

    @property
    def reply_timeout_now_s(self) -> float:
        """The reply timeout in force now (s): adapted to the measured round trips."""
        return self.rtt.timeout_s

    def record_fault(self, fault: str, **fields) -> None:
        """Report a recovered fault (a ``fault`` record for the capture log)."""
        self.fault_events.append(
            {"type": "fault", "t": self.clock.monotonic(), "fault": fault, **fields}
        )

    def drain_faults(self) -> list[dict]:
        """The fault events reported since the last call (oldest first), removed."""
        out = []
        while True:
            try:
                out.append(self.fault_events.popleft())
            except IndexError:
                return out

    def keepalive(self) -> int:
        """Send KEEPALIVE (resets the sleep timer); return the sleep limit (ms, 0 = never)."""
        with self.lock:
            reply = self._request(KeepAlive())
            self.last_keepalive = self.clock.monotonic()
            self.sleep_limit_ms = reply.sleep_limit_ms  # type: ignore[union-attr]
            self.stats.keepalives += 1
            return self.sleep_limit_ms

    def keepalive_due(self) -> bool:
        """Whether a KEEPALIVE must be sent now to stay clear of the sleep timer."""
        if self.last_keepalive is None:
            return True
        interval = self.keepalive_interval_s
        if self.sleep_limit_ms:
            interval = min(interval, 0.5 * self.sleep_limit_ms / 1000.0)
        return self.clock.monotonic() - self.last_keepalive >= interval

    def maybe_keepalive(self) -> None:
        with self.lock:
            if self.keepalive_due():
                self.keepalive()

    def battery_mv(self) -> int:
        """Battery voltage (mV)."""
        reply = self.request(GetBatteryLevel())
        self.last_battery_mv = reply.millivolts  # type: ignore[union-attr]
        return self.last_battery_mv

    def check_battery(self, min_mv: int) -> int:
        """Read the battery; raise :class:`BatteryLowError` below ``min_mv``."""
        mv = self.battery_mv()
        if mv < min_mv:
            raise BatteryLowError(
                f"NXT battery at {mv} mV, below nxt.battery_min_mv = {min_mv} mV: "
                "replace or recharge the batteries"
            )
        return mv

    def handshake(self) -> None:
        """First contact: KEEPALIVE, with a clear error if the brick does not answer."""
        try:
            self.keepalive()
        except ReplyTimeoutError as exc:
            raise BrickNotAnsweringError(
                f"the NXT brick does not answer on {self.port_name}: is it switched on, paired, "
                "and is this the right port (nxt.port)? For a real brick check that the "
                "rfcomm device is bound to the brick's Bluetooth address"
            ) from exc

    def output_state(self, port: int) -> OutputState:
        return self.request(GetOutputState(port=port))  # type: ignore[return-value]

    def input_values(self, port: int) -> InputValues:
        return self.request(GetInputValues(port=port))  # type: ignore[return-value]

    def close(self) -> None:
        with self.lock:
            self.closed = True
            if self.transport is not None:
                with contextlib.suppress(OSError):
                    self.transport.close()
                self.transport = None

    # ------------------------------------------------------------------ internals

    def _request(self, cmd: Command) -> Reply | None:
        budget = RetryBudget(self.retries)
        last_exc: Exception | None = None
        kind = "reply_lost"
        aligned = True  # the reply stream is known to be in step (round trips can be measured)
        while True:
            if budget.attempts:
                self.stats.retries += 1
                log.info(
                    "retrying %s (attempt %d): %s",
                    type(cmd).__name__,
                    budget.attempts + 1,
                    last_exc,
                )
            answered = False
            try:
                reply = self._exchange(cmd, measure=aligned)
                if budget.attempts and kind != "link_lost":  # a reconnect reports itself
                    self.record_fault(
                        kind,
                        recovered=True,
                        command=type(cmd).__name__,
                        attempts=budget.attempts + 1,
                        detail=str(last_exc),
                    )
                return reply
            except (ReplyTimeoutError, MalformedReplyError, FramingError) as exc:
                last_exc = exc
                if not isinstance(exc, ReplyTimeoutError):
                    kind = "reply_garbled"
                try:
                    self._resync()
                    answered = aligned = True
                except ReplyTimeoutError as exc2:
                    last_exc, aligned = exc2, False
                except OSError as exc2:
                    last_exc, aligned = exc2, False
                    self._reconnect(exc2)
                    answered, kind = True, "link_lost"
            except OSError as exc:  # serial.SerialException is an OSError
                last_exc, aligned = exc, False
                self._reconnect(exc)
                answered, kind = True, "link_lost"
            if not budget.spend(answered) or not cmd.idempotent:
                break
        if isinstance(last_exc, ReplyTimeoutError | OSError):
            err = ReplyTimeoutError(
                f"no valid reply to {type(cmd).__name__} from the brick on {self.port_name} "
                f"after {budget.attempts} attempt(s)"
                + ("" if cmd.idempotent else " (not retried: unsafe to repeat)")
                + f": {last_exc}"
            )
            err.brick_answered = answered
            raise err from last_exc
        raise last_exc  # type: ignore[misc]

    def _exchange(self, cmd: Command, measure: bool = True) -> Reply | None:
        """Send ``cmd`` once and read its reply.

        Args:
            measure: the reply stream is in step, so the round trip of this exchange is a
                valid sample for the adaptive timeout (unless a stale reply turns up).
        """
        tr = self._transport()
        self._drain_stale(tr)
        self.stats.requests += 1
        self.stats.opcodes.append(int(cmd.OPCODE))
        tr.write(cmd.packet())
        if not cmd.reply:
            return None
        sent = self.clock.monotonic()
        timeout = self.rtt.timeout_s
        deadline = sent + timeout
        while True:
            telegram = self._read_packet(tr, deadline, cmd, timeout)
            if len(telegram) >= 2 and telegram[0] == REPLY and telegram[1] != cmd.OPCODE:
                self.stats.stale_replies += 1
                measure = False
                continue  # a late reply to an earlier command
            try:
                reply = parse_reply(telegram, int(cmd.OPCODE))
            except MalformedReplyError:
                self.stats.malformed += 1
                raise
            port = getattr(cmd, "port", None)
            if isinstance(reply, OutputState | InputValues) and reply.port != port:
                self.stats.stale_replies += 1
                measure = False
                continue  # a late reply for another port
            if measure:
                self.rtt.sample(self.clock.monotonic() - sent)
            self._activity()
            return reply

    def _resync(self) -> None:
        """Re-align request and reply streams after a timeout or a garbled reply.

        Replies carry no sequence number, so a reply that comes after its timeout could be
        taken for the answer to a later request with the same opcode. The brick answers in
        order, so a KEEPALIVE is sent as a barrier and everything read before its reply is
        discarded (and the brick's sleep timer is reset on the way).

        Raises:
            ReplyTimeoutError: the barrier was not answered (after the retries).
        """
        self._flush()
        barrier = KeepAlive()
        for _ in range(1 + min(1, self.retries)):
            tr = self._transport()
            self._drain_stale(tr)
            self.stats.requests += 1
            self.stats.resyncs += 1
            tr.write(barrier.packet())
            timeout = self.rtt.timeout_s
            deadline = self.clock.monotonic() + timeout
            try:
                while True:
                    # the barrier's round trip is not measured: its reply may be the answer
                    # to an earlier barrier
                    telegram = self._read_packet(tr, deadline, barrier, timeout)
                    if telegram[:2] == bytes([REPLY, barrier.OPCODE]):
                        try:
                            reply = parse_reply(telegram, int(barrier.OPCODE))
                        except ProtocolError:
                            break
                        self.sleep_limit_ms = reply.sleep_limit_ms  # type: ignore[union-attr]
                        self.last_keepalive = self.clock.monotonic()
                        self._activity()
                        return
                    self.stats.stale_replies += 1
            except (ReplyTimeoutError, FramingError):
                self._flush()
        raise ReplyTimeoutError(
            f"the brick on {self.port_name} does not answer a KEEPALIVE after a failed reply"
        )

    def _read_exact(
        self, tr: Transport, n: int, deadline: float, cmd: Command, timeout: float
    ) -> bytes:
        buf = bytearray()
        while len(buf) < n:
            chunk = tr.read(n - len(buf))
            if chunk:
                buf += chunk
                continue
            if self.clock.monotonic() >= deadline:
                self.stats.timeouts += 1
                self.rtt.backoff()
                raise ReplyTimeoutError(
                    f"timeout after {timeout:.2f} s waiting for the reply to "
                    f"{type(cmd).__name__} ({len(buf)} of {n} bytes received)"
                )
        return bytes(buf)

    def _read_packet(self, tr: Transport, deadline: float, cmd: Command, timeout: float) -> bytes:
        head = self._read_exact(tr, 2, deadline, cmd, timeout)
        n = head[0] | (head[1] << 8)
        if not 0 < n <= 64:
            self.stats.malformed += 1
            raise FramingError(f"reply length prefix {n} (must be 1..64)")
        return self._read_exact(tr, n, deadline, cmd, timeout)

    def _activity(self) -> None:
        for hook in self.on_activity:
            hook()

    def _drain_stale(self, tr: Transport) -> None:
        """Read whatever is waiting before a request: it can only be stale."""
        try:
            waiting = tr.in_waiting
        except (AttributeError, TypeError):
            waiting = 0
        if waiting:
            data = tr.read(waiting)
            self.stats.bytes_flushed += len(data)

    def _flush(self) -> None:
        if self.transport is None:
            return
        with contextlib.suppress(OSError):
            self.transport.reset_input_buffer()

    def _transport(self) -> Transport:
        if self.transport is None:
            self._reconnect(None)
        assert self.transport is not None
        return self.transport

    def _reconnect(self, cause: Exception | None) -> None:
        """Reopen the port after a link failure, then run the ``on_reconnect`` hooks."""
        if self.transport is not None:
            with contextlib.suppress(OSError):
                self.transport.close()
            self.transport = None
        if self.opener is None or self.reconnect_attempts == 0 or self._in_reconnect:
            raise LinkLostError(
                f"lost the link to the NXT on {self.port_name} ({cause}); the motors keep "
                "running after a link loss: switch the brick off if it is moving"
            ) from cause
        last: Exception | None = cause
        for _ in range(self.reconnect_attempts):
            self.clock.sleep(self.reconnect_delay_s)
            try:
                self.transport = self.opener()
            except (OSError, RobotError) as exc:
                last = exc
                continue
            self.stats.reconnects += 1
            log.warning("reconnected to the NXT on %s after: %s", self.port_name, cause)
            self._in_reconnect = True
            try:
                for hook in list(self.on_reconnect):
                    hook()
            except (OSError, ProtocolError, RobotError) as exc:
                last = exc
                self.transport = None
                continue
            finally:
                self._in_reconnect = False
            self.record_fault(
                "link_lost",
                recovered=True,
                action="port reopened, reconnect hooks run (the robot stops the motors)",
                detail=str(cause),
            )
            return
        self.link_dead = f"could not reopen the port: {last}"
        why = "the port is gone" if isinstance(last, PortNotFoundError) else str(last)
        raise LinkLostError(
            f"lost the link to the NXT on {self.port_name} and could not reopen it after "
            f"{self.reconnect_attempts} attempts over "
            f"{self.reconnect_attempts * self.reconnect_delay_s:.1f} s ({why}); the motors "
            "keep running after a link loss, until the tacho limit of the motion under way "
            "(every motion has one): switch the brick off if it is moving, check Bluetooth "
            "and the port"
        ) from last
