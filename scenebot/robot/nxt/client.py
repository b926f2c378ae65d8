"""NXT direct-command client over a pyserial-like transport.

One request is in flight at a time (a re-entrant lock serialises the control loop and the
watchdog thread). Every reply is validated (type, opcode echo, port echo, status, length).
Commands that are safe to repeat (:attr:`Command.idempotent`) are retried after a timeout, a
malformed reply or a reconnect; the others raise :class:`ReplyTimeoutError` so the caller can
find out what happened (e.g. by reading the motor state) instead of doing it twice.

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
from typing import Protocol

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

log = logging.getLogger(__name__)

READ_SLICE_S = 0.05
"""Transport read timeout (s): the client loops over short reads until its own deadline."""


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


def open_serial(port: str, baudrate: int = 115200, timeout_s: float = READ_SLICE_S) -> Transport:
    """Open ``port`` with pyserial (exclusive lock), translating failures into clear errors.

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
                f"serial port {port} does not exist: check robot.nxt.port in the config; for a "
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
        reply_timeout_s: float = 1.0,
        retries: int = 2,
        keepalive_interval_s: float = 60.0,
        opener: Callable[[], Transport] | None = None,
        reconnect_attempts: int = 0,
        reconnect_delay_s: float = 0.5,
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
        self._in_reconnect = False
        self.closed = False
        self.link_dead: str | None = None  # set when reopening the port failed for good

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
            if not isinstance(cmd, KeepAlive):
                self.maybe_keepalive()
            return self._request(cmd)

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
                f"NXT battery at {mv} mV, below robot.nxt.battery_min_mv = {min_mv} mV: "
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
                "and is this the right port (robot.nxt.port)? For a real brick check that the "
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
        attempts = 1 + (self.retries if cmd.idempotent else 0)
        last_exc: Exception | None = None
        for attempt in range(attempts):
            if attempt:
                self.stats.retries += 1
                log.info("retrying %s (attempt %d): %s", type(cmd).__name__, attempt + 1, last_exc)
            try:
                return self._exchange(cmd)
            except (ReplyTimeoutError, MalformedReplyError, FramingError) as exc:
                last_exc = exc
                try:
                    self._resync()
                except ReplyTimeoutError as exc2:
                    last_exc = exc2
                except OSError as exc2:
                    last_exc = exc2
                    self._reconnect(exc2)
            except OSError as exc:  # serial.SerialException is an OSError
                last_exc = exc
                self._reconnect(exc)
        if isinstance(last_exc, ReplyTimeoutError | OSError):
            raise ReplyTimeoutError(
                f"no valid reply to {type(cmd).__name__} from the brick on {self.port_name} "
                f"after {attempts} attempt(s)"
                + ("" if cmd.idempotent else " (not retried: unsafe to repeat)")
                + f": {last_exc}"
            ) from last_exc
        raise last_exc  # type: ignore[misc]

    def _exchange(self, cmd: Command) -> Reply | None:
        tr = self._transport()
        self._drain_stale(tr)
        self.stats.requests += 1
        self.stats.opcodes.append(int(cmd.OPCODE))
        tr.write(cmd.packet())
        if not cmd.reply:
            return None
        deadline = self.clock.monotonic() + self.reply_timeout_s
        while True:
            telegram = self._read_packet(tr, deadline, cmd)
            if len(telegram) >= 2 and telegram[0] == REPLY and telegram[1] != cmd.OPCODE:
                self.stats.stale_replies += 1
                continue  # a late reply to an earlier command
            try:
                reply = parse_reply(telegram, int(cmd.OPCODE))
            except MalformedReplyError:
                self.stats.malformed += 1
                raise
            port = getattr(cmd, "port", None)
            if isinstance(reply, OutputState | InputValues) and reply.port != port:
                self.stats.stale_replies += 1
                continue  # a late reply for another port
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
            deadline = self.clock.monotonic() + self.reply_timeout_s
            try:
                while True:
                    telegram = self._read_packet(tr, deadline, barrier)
                    if telegram[:2] == bytes([REPLY, barrier.OPCODE]):
                        try:
                            reply = parse_reply(telegram, int(barrier.OPCODE))
                        except ProtocolError:
                            break
                        self.sleep_limit_ms = reply.sleep_limit_ms  # type: ignore[union-attr]
                        self.last_keepalive = self.clock.monotonic()
                        return
                    self.stats.stale_replies += 1
            except (ReplyTimeoutError, FramingError):
                self._flush()
        raise ReplyTimeoutError(
            f"the brick on {self.port_name} does not answer a KEEPALIVE after a failed reply"
        )

    def _read_exact(self, tr: Transport, n: int, deadline: float, cmd: Command) -> bytes:
        buf = bytearray()
        while len(buf) < n:
            chunk = tr.read(n - len(buf))
            if chunk:
                buf += chunk
                continue
            if self.clock.monotonic() >= deadline:
                self.stats.timeouts += 1
                raise ReplyTimeoutError(
                    f"timeout after {self.reply_timeout_s:.2f} s waiting for the reply to "
                    f"{type(cmd).__name__} ({len(buf)} of {n} bytes received)"
                )
        return bytes(buf)

    def _read_packet(self, tr: Transport, deadline: float, cmd: Command) -> bytes:
        head = self._read_exact(tr, 2, deadline, cmd)
        n = head[0] | (head[1] << 8)
        if not 0 < n <= 64:
            self.stats.malformed += 1
            raise FramingError(f"reply length prefix {n} (must be 1..64)")
        return self._read_exact(tr, n, deadline, cmd)

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
            return
        self.link_dead = f"could not reopen the port: {last}"
        raise LinkLostError(
            f"lost the link to the NXT on {self.port_name} and could not reopen it after "
            f"{self.reconnect_attempts} attempts ({last}); the motors keep running after a "
            "link loss: switch the brick off if it is moving, check Bluetooth and the port"
        ) from last
