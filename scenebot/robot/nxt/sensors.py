"""NXT sensors over direct commands: touch bumpers, LEGO ultrasonic, HiTechnic compass,
plus wheel odometry from tacho counts and stall detection from rotation counts.

I2C ("low speed") transactions are LSWRITE (address byte, register, [value]) -> poll
LSGETSTATUS until the reply bytes are ready -> LSREAD (always a 20-byte reply). The firmware
answers 0xE0 (channel not configured or busy) for ~20 ms after SETINPUTMODE, and 0x20 while a
transaction is pending; both are waited out. A port that stays "not configured" reports a
different sensor type in GETINPUTVALUES when the brick has rebooted: that raises
:class:`SensorModeLost` so the robot can set the modes again.

LSWRITE and LSREAD are unsafe to repeat on their own (one queues a transfer, the other
consumes the receive buffer), so the client does not retry them; but the transactions these
sensors use (read registers, write a mode register with the same value) can be redone from
the start. A lost or garbled reply anywhere in one, or a transfer still pending after
``pending_timeout_s`` on a port that kept its mode, redoes the whole transaction, under the
client's :class:`~scenebot.robot.nxt.client.RetryBudget` (few attempts while the brick is
silent, more while it answers and only replies are lost); each redone transaction is reported
as a fault event.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from scenebot.robot.base import Pose2D
from scenebot.robot.nxt.client import Clock, NxtClient, RetryBudget
from scenebot.robot.nxt.protocol import (
    BusError,
    ChannelBusyError,
    FramingError,
    LsGetStatus,
    LsRead,
    LsWrite,
    MalformedReplyError,
    PendingTransactionError,
    ProtocolError,
    ReplyTimeoutError,
    SensorMode,
    SensorType,
    SetInputMode,
)

I2C_ADDRESS = 0x02
"""8-bit I2C address of both the LEGO ultrasonic and the HiTechnic compass."""
REG_COMMAND = 0x41
REG_MEASUREMENT = 0x42
US_CONTINUOUS = 0x02
COMPASS_MEASURE = 0x00


class SensorModeLost(ProtocolError):
    """A sensor port no longer has the type scenebot set (the brick rebooted)."""


class SensorReadError(ProtocolError):
    """An I2C sensor returned an impossible value or no data."""


class TouchSensor:
    """A touch switch in boolean mode (scaled value 1 = pressed)."""

    def __init__(self, client: NxtClient, port: int, name: str):
        self.client, self.port, self.name = client, port, name
        self._last = False

    def setup(self) -> None:
        self.client.request(
            SetInputMode(port=self.port, sensor_type=SensorType.SWITCH, sensor_mode=0x20)
        )

    def pressed(self) -> bool:
        """Whether the switch is pressed.

        Raises:
            SensorModeLost: the port is no longer configured as a switch.
        """
        v = self.client.input_values(self.port)
        if v.sensor_type != SensorType.SWITCH:
            raise SensorModeLost(
                f"{self.name} on sensor port {self.port + 1} reports type "
                f"0x{v.sensor_type:02X} instead of SWITCH"
            )
        if v.valid:
            self._last = v.scaled != 0
        return self._last


class I2CSensor:
    """A digital sensor on a low-speed port.

    Args:
        client: the brick.
        port: sensor port 0-3.
        sensor_type: ``LOWSPEED_9V`` (ultrasonic) or ``LOWSPEED`` (compass).
        clock: time source for the polling waits.
        pending_timeout_s: how long 0xE0 / 0x20 may last before giving up.
        poll_s: pause between LSGETSTATUS polls.
        retries: extra attempts of a whole transaction after a bus error.
    """

    def __init__(
        self,
        client: NxtClient,
        port: int,
        sensor_type: int,
        clock: Clock,
        name: str,
        pending_timeout_s: float = 0.25,
        poll_s: float = 0.005,
        retries: int = 2,
    ):
        self.client, self.port, self.sensor_type, self.clock = client, port, sensor_type, clock
        self.name = name
        self.pending_timeout_s, self.poll_s, self.retries = pending_timeout_s, poll_s, retries

    def setup(self) -> None:
        """Set the port type; subclasses then program the sensor."""
        self.client.request(
            SetInputMode(port=self.port, sensor_type=self.sensor_type, sensor_mode=SensorMode.RAW)
        )

    def _check_mode(self) -> None:
        v = self.client.input_values(self.port)
        if v.sensor_type != self.sensor_type:
            raise SensorModeLost(
                f"{self.name} on sensor port {self.port + 1} reports type 0x{v.sensor_type:02X} "
                f"instead of 0x{self.sensor_type:02X}"
            )

    def _until_ready(self, fn):
        """Call ``fn`` until it stops answering pending/busy, up to ``pending_timeout_s``."""
        deadline = self.clock.monotonic() + self.pending_timeout_s
        while True:
            try:
                return fn()
            except (ChannelBusyError, PendingTransactionError):
                if self.clock.monotonic() >= deadline:
                    self._check_mode()  # raises SensorModeLost after a reboot
                    raise
                self.clock.sleep(self.poll_s)

    def _attempt(self, tx: bytes, rx_len: int) -> bytes:
        """One try of a transaction: LSWRITE, poll LSGETSTATUS, LSREAD."""
        self._until_ready(
            lambda: self.client.request(LsWrite(port=self.port, tx=tx, rx_len=rx_len))
        )

        # LSWRITE only queues the transfer: its outcome (e.g. a NACK = bus error)
        # shows in LSGETSTATUS, for writes as for reads
        def ready() -> int:
            st = self.client.request(LsGetStatus(port=self.port))
            if st.bytes_ready < rx_len:  # type: ignore[union-attr]
                raise PendingTransactionError(int(LsGetStatus.OPCODE))
            return st.bytes_ready  # type: ignore[union-attr]

        self._until_ready(ready)
        if rx_len == 0:
            return b""
        return self.client.request(LsRead(port=self.port)).data  # type: ignore[union-attr]

    def transaction(self, tx: bytes, rx_len: int) -> bytes:
        """One I2C write(+read) transaction; returns ``rx_len`` bytes.

        The whole transaction is redone after a bus error (up to ``retries`` times) and after
        a lost or garbled reply (under the client's retry budget; see the module doc).

        Raises:
            SensorModeLost: the port lost its mode (brick reboot).
            BusError: the bus kept failing after ``retries`` repeats.
            ReplyTimeoutError: replies kept being lost, or the transfer stayed pending (names
                the sensor and its port).
            SensorReadError: fewer bytes than asked for.
        """
        bus_errors = 0
        budget = RetryBudget(self.client.retries)
        while True:
            try:
                data = self._attempt(tx, rx_len)
            except BusError:
                bus_errors += 1
                if bus_errors > self.retries:
                    raise
                continue
            except (
                ReplyTimeoutError,
                MalformedReplyError,
                FramingError,
                ChannelBusyError,
                PendingTransactionError,
            ) as exc:
                # a reply lost (the brick may or may not be there), garbled, or a transfer
                # still pending/busy after pending_timeout_s with the mode intact (it answers)
                answered = bool(getattr(exc, "brick_answered", True))
                if not budget.spend(answered):
                    err = ReplyTimeoutError(
                        f"{self.name} on sensor port {self.port + 1}: no complete I2C "
                        f"transaction after {budget.attempts} attempt(s) ({exc}); check the "
                        "Bluetooth link, the brick's batteries and the sensor cable"
                    )
                    err.brick_answered = answered
                    raise err from exc
                continue
            if len(data) < rx_len:
                raise SensorReadError(
                    f"{self.name}: LSREAD returned {len(data)} bytes, expected {rx_len}"
                )
            if budget.attempts:
                self.client.record_fault(
                    "reply_lost",
                    recovered=True,
                    sensor=self.name,
                    port=self.port + 1,
                    action="I2C transaction redone from the start",
                    attempts=budget.attempts + 1,
                )
            return data[:rx_len]

    def write_register(self, reg: int, value: int) -> None:
        self.transaction(bytes([I2C_ADDRESS, reg, value]), 0)

    def read_registers(self, reg: int, n: int) -> bytes:
        return self.transaction(bytes([I2C_ADDRESS, reg]), n)


class Ultrasonic(I2CSensor):
    """LEGO ultrasonic rangefinder in continuous mode; distance register 0x42 (cm)."""

    def __init__(self, client: NxtClient, port: int, clock: Clock):
        super().__init__(client, port, SensorType.LOWSPEED_9V, clock, "ultrasonic sensor")

    def setup(self) -> None:
        super().setup()
        self.write_register(REG_COMMAND, US_CONTINUOUS)

    def distance_cm(self) -> int:
        """Range in whole cm; 255 = no echo."""
        return self.read_registers(REG_MEASUREMENT, 1)[0]


def compass_to_ccw(h_deg: float, convention: str, offset_deg: float) -> float:
    """Convert a compass reading into a counter-clockwise heading in ``[0, 360)`` degrees.

    Args:
        h_deg: heading as the sensor reports it.
        convention: ``"clockwise"`` (the sensor counts clockwise: returns ``360 - h``) or
            ``"counter_clockwise"``.
        offset_deg: added after the conversion.
    """
    if convention == "clockwise":
        h_deg = 360.0 - h_deg
    elif convention != "counter_clockwise":
        raise ValueError(f"compass convention {convention!r} (clockwise|counter_clockwise)")
    return (h_deg + offset_deg) % 360.0


class HiTechnicCompass(I2CSensor):
    """HiTechnic compass: heading = 2 * reg 0x42 + reg 0x43 (degrees, clockwise).

    ``convention`` and ``offset_deg``: see :func:`compass_to_ccw` (``nxt.compass_convention``,
    ``nxt.compass_offset_deg``).
    """

    def __init__(
        self,
        client: NxtClient,
        port: int,
        clock: Clock,
        convention: str,
        offset_deg: float,
    ):
        super().__init__(client, port, SensorType.LOWSPEED, clock, "compass")
        self.convention, self.offset_deg = convention, offset_deg

    def setup(self) -> None:
        super().setup()
        self.write_register(REG_COMMAND, COMPASS_MEASURE)

    def raw_heading_deg(self) -> int:
        """The sensor's own heading, 0-359, in its own (clockwise) convention."""
        two_deg, one_deg = self.read_registers(REG_MEASUREMENT, 2)
        h = 2 * two_deg + one_deg
        if h > 359 or one_deg > 1:
            raise SensorReadError(
                f"compass registers 0x42/0x43 = {two_deg}/{one_deg} give heading {h} (0-359 "
                "expected): check the sensor on the compass port is a HiTechnic compass"
            )
        return h

    def heading_ccw_deg(self) -> float:
        """Counter-clockwise heading in ``[0, 360)`` degrees (robot convention)."""
        return compass_to_ccw(self.raw_heading_deg(), self.convention, self.offset_deg)


@dataclass
class Odometry:
    """Differential-drive dead reckoning from wheel encoder counts.

    Attributes:
        wheel_radius_m: wheel radius (m).
        wheel_base_m: distance between the wheels (m).
        pose: current pose in the odometry frame.
    """

    wheel_radius_m: float
    wheel_base_m: float
    pose: Pose2D
    _left: float | None = None
    _right: float | None = None

    def rebaseline(self, left_deg: float, right_deg: float) -> None:
        """Take these counts as the reference without moving the pose (after a reset)."""
        self._left, self._right = left_deg, right_deg

    def wheel_m(self, deg: float) -> float:
        return math.radians(deg) * self.wheel_radius_m

    def update(self, left_deg: float, right_deg: float) -> tuple[float, float]:
        """Integrate new cumulative counts (deg, forward positive).

        Returns:
            ``(distance_m, angle_rad)`` moved since the previous update.
        """
        if self._left is None or self._right is None:
            self.rebaseline(left_deg, right_deg)
            return 0.0, 0.0
        dl = self.wheel_m(left_deg - self._left)
        dr = self.wheel_m(right_deg - self._right)
        self._left, self._right = left_deg, right_deg
        ds = 0.5 * (dl + dr)
        dth = (dr - dl) / self.wheel_base_m
        mid = self.pose.theta + 0.5 * dth
        theta = (self.pose.theta + dth) % (2.0 * math.pi)
        self.pose = Pose2D(
            self.pose.x + ds * math.cos(mid), self.pose.y + ds * math.sin(mid), theta
        )
        return ds, dth


class StallDetector:
    """A powered wheel whose rotation count moves less than ``min_deg`` within ``window_s``.

    Feed one sample per poll with :meth:`update`; :meth:`reset` when the motor is (re)started.
    """

    def __init__(self, window_s: float, min_deg: float):
        self.window_s, self.min_deg = window_s, min_deg
        self._samples: deque[tuple[float, float]] = deque()

    def reset(self) -> None:
        self._samples.clear()

    def update(self, t: float, count_deg: float) -> bool:
        """Add a sample; return True if the wheel is stalled."""
        self._samples.append((t, count_deg))
        while len(self._samples) > 2 and t - self._samples[1][0] >= self.window_s:
            self._samples.popleft()
        t0, c0 = self._samples[0]
        if t - t0 < self.window_s:
            return False
        return abs(count_deg - c0) < self.min_deg
