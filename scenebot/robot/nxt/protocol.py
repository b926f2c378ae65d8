"""LEGO NXT direct-command telegrams over Bluetooth (LEGO Bluetooth Developer Kit, appendix 2).

A Bluetooth packet is a 2-byte little-endian length followed by a *telegram*::

    [len_lo, len_hi] [type] [opcode] [payload ...]

``type`` is ``0x00`` (direct command, reply wanted), ``0x80`` (direct command, no reply) or
``0x02`` (reply). A reply telegram is ``[0x02, opcode, status, payload ...]``; ``status`` 0 is
success, anything else is one of the firmware error codes below and becomes a typed
:class:`DirectCommandError` subclass. Multi-byte fields are little-endian; ``SBYTE``/``SWORD``/
``SLONG`` are signed, ``UBYTE``/``UWORD``/``ULONG`` unsigned.

Both directions are implemented (``encode``/``parse`` for commands and replies) so that the
driver and the brick emulator share one byte-exact definition and the tests can check both.
"""

from __future__ import annotations

import enum
import struct
from dataclasses import dataclass
from typing import ClassVar

DIRECT_REPLY = 0x00
"""Telegram type: direct command, reply required."""
DIRECT_NO_REPLY = 0x80
"""Telegram type: direct command, no reply."""
REPLY = 0x02
"""Telegram type: reply."""
MAX_TELEGRAM = 64
"""Largest telegram (bytes, without the 2-byte Bluetooth length) a direct command may have."""
LS_READ_DATA_BYTES = 16
"""LSREAD always returns a 16-byte data field (padded with zeros)."""
LS_MAX_BYTES = 16
"""Largest I2C transfer of one LSWRITE / LSREAD."""
ALL_MOTORS = 0xFF
"""SETOUTPUTSTATE port meaning all three motor ports."""


class Opcode(enum.IntEnum):
    """Direct-command opcodes used by scenebot."""

    SET_OUTPUT_STATE = 0x04
    SET_INPUT_MODE = 0x05
    GET_OUTPUT_STATE = 0x06
    GET_INPUT_VALUES = 0x07
    RESET_MOTOR_POSITION = 0x0A
    GET_BATTERY_LEVEL = 0x0B
    KEEP_ALIVE = 0x0D
    LS_GET_STATUS = 0x0E
    LS_WRITE = 0x0F
    LS_READ = 0x10


class OutputMode(enum.IntFlag):
    """SETOUTPUTSTATE mode bits."""

    COAST = 0x00
    MOTORON = 0x01
    BRAKE = 0x02
    REGULATED = 0x04


class RegulationMode(enum.IntEnum):
    IDLE = 0x00
    MOTOR_SPEED = 0x01
    MOTOR_SYNC = 0x02


class RunState(enum.IntEnum):
    IDLE = 0x00
    RAMPUP = 0x10
    RUNNING = 0x20
    RAMPDOWN = 0x40


class SensorType(enum.IntEnum):
    NO_SENSOR = 0x00
    SWITCH = 0x01
    TEMPERATURE = 0x02
    REFLECTION = 0x03
    ANGLE = 0x04
    LIGHT_ACTIVE = 0x05
    LIGHT_INACTIVE = 0x06
    SOUND_DB = 0x07
    SOUND_DBA = 0x08
    CUSTOM = 0x09
    LOWSPEED = 0x0A
    LOWSPEED_9V = 0x0B


class SensorMode(enum.IntEnum):
    RAW = 0x00
    BOOLEAN = 0x20
    TRANSITION_COUNT = 0x40
    PERIOD_COUNTER = 0x60
    PCT_FULL_SCALE = 0x80
    CELSIUS = 0xA0
    FAHRENHEIT = 0xC0
    ANGLE_STEPS = 0xE0


# --------------------------------------------------------------------------- errors


class ProtocolError(Exception):
    """Any violation of the NXT protocol (bad framing, malformed reply, error status)."""


class FramingError(ProtocolError):
    """A Bluetooth packet whose length prefix is impossible (0 or > 64 bytes)."""


class MalformedReplyError(ProtocolError):
    """A reply telegram with a wrong type, opcode, length or field value."""


class MalformedCommandError(ProtocolError):
    """A command telegram with a wrong type byte or too short (the emulator's side)."""


class ReplyTimeoutError(ProtocolError):
    """No complete reply arrived within the read timeout.

    Attributes:
        brick_answered: the brick answered a KEEPALIVE barrier after the lost reply (the link
            is alive and only this reply was lost), so a caller that can redo the whole
            transaction (an I2C register read) may do so.
    """

    brick_answered: bool = False


class DirectCommandError(ProtocolError):
    """The brick answered with a non-zero status byte.

    Attributes:
        status: the status byte (``0x20`` ... ``0xFF``).
        opcode: the opcode of the command that failed.
    """

    status: ClassVar[int] = -1
    meaning: ClassVar[str] = "unknown error status"

    def __init__(self, opcode: int, status: int | None = None):
        self.opcode = opcode
        if status is not None:
            self.status = status  # type: ignore[misc]
        super().__init__(
            f"NXT replied status 0x{self.status:02X} ({self.meaning}) to opcode 0x{opcode:02X}"
        )


def _status_error(name: str, code: int, meaning: str) -> type[DirectCommandError]:
    return type(name, (DirectCommandError,), {"status": code, "meaning": meaning})


PendingTransactionError = _status_error(
    "PendingTransactionError", 0x20, "pending communication transaction in progress"
)
MailboxEmptyError = _status_error("MailboxEmptyError", 0x40, "specified mailbox queue is empty")
RequestFailedError = _status_error("RequestFailedError", 0xBD, "request failed")
UnknownOpcodeError = _status_error("UnknownOpcodeError", 0xBE, "unknown command opcode")
InsanePacketError = _status_error("InsanePacketError", 0xBF, "insane packet")
OutOfRangeError = _status_error("OutOfRangeError", 0xC0, "data contains out-of-range values")
BusError = _status_error("BusError", 0xDD, "communication bus error")
NoFreeMemoryError = _status_error(
    "NoFreeMemoryError", 0xDE, "no free memory in communication buffer"
)
ChannelInvalidError = _status_error(
    "ChannelInvalidError", 0xDF, "specified channel/connection is not valid"
)
ChannelBusyError = _status_error(
    "ChannelBusyError", 0xE0, "specified channel/connection not configured or busy"
)
NoActiveProgramError = _status_error("NoActiveProgramError", 0xEC, "no active program")
IllegalSizeError = _status_error("IllegalSizeError", 0xED, "illegal size specified")
IllegalMailboxError = _status_error(
    "IllegalMailboxError", 0xEE, "illegal mailbox queue ID specified"
)
InvalidFieldError = _status_error(
    "InvalidFieldError", 0xEF, "attempted to access invalid field of a structure"
)
BadIoError = _status_error("BadIoError", 0xF0, "bad input or output specified")
InsufficientMemoryError = _status_error(
    "InsufficientMemoryError", 0xFB, "insufficient memory available"
)
BadArgumentsError = _status_error("BadArgumentsError", 0xFF, "bad arguments")

STATUS_ERRORS: dict[int, type[DirectCommandError]] = {
    cls.status: cls
    for cls in (
        PendingTransactionError,
        MailboxEmptyError,
        RequestFailedError,
        UnknownOpcodeError,
        InsanePacketError,
        OutOfRangeError,
        BusError,
        NoFreeMemoryError,
        ChannelInvalidError,
        ChannelBusyError,
        NoActiveProgramError,
        IllegalSizeError,
        IllegalMailboxError,
        InvalidFieldError,
        BadIoError,
        InsufficientMemoryError,
        BadArgumentsError,
    )
}
"""Status byte -> error class (the direct-command error table of the BDK)."""


def status_error(opcode: int, status: int) -> DirectCommandError:
    """The typed error for a non-zero ``status`` (an undocumented code gives the base class)."""
    cls = STATUS_ERRORS.get(status)
    if cls is None:
        return DirectCommandError(opcode, status)
    return cls(opcode)


# --------------------------------------------------------------------------- framing


def frame(telegram: bytes) -> bytes:
    """Prefix a telegram with its 2-byte little-endian Bluetooth length."""
    if not 0 < len(telegram) <= MAX_TELEGRAM:
        raise FramingError(f"telegram of {len(telegram)} bytes (must be 1..{MAX_TELEGRAM})")
    return struct.pack("<H", len(telegram)) + telegram


class FrameDecoder:
    """Incremental Bluetooth packet decoder: feed bytes as they arrive, get whole telegrams.

    An impossible length prefix raises :class:`FramingError` and drops the buffered bytes
    (the stream cannot be resynchronised from inside a bad packet).
    """

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> list[bytes]:
        """Add ``data``; return the complete telegrams now available (possibly none)."""
        self._buf += data
        out: list[bytes] = []
        while len(self._buf) >= 2:
            n = self._buf[0] | (self._buf[1] << 8)
            if not 0 < n <= MAX_TELEGRAM:
                self._buf.clear()
                raise FramingError(f"Bluetooth length prefix {n} (must be 1..{MAX_TELEGRAM})")
            if len(self._buf) < 2 + n:
                break
            out.append(bytes(self._buf[2 : 2 + n]))
            del self._buf[: 2 + n]
        return out

    @property
    def pending(self) -> int:
        """Bytes of an incomplete packet currently buffered."""
        return len(self._buf)

    def clear(self) -> None:
        self._buf.clear()


# --------------------------------------------------------------------------- commands


@dataclass(frozen=True)
class Command:
    """Base of all direct commands. ``reply`` selects telegram type 0x00 (True) or 0x80."""

    OPCODE: ClassVar[Opcode]
    FORMAT: ClassVar[str] = ""
    reply: bool = True

    @property
    def idempotent(self) -> bool:
        """Whether sending the command twice has the same effect as once (safe to retry)."""
        return True

    def fields(self) -> tuple:
        return ()

    def encode(self) -> bytes:
        """The telegram (without Bluetooth length prefix)."""
        head = bytes([DIRECT_REPLY if self.reply else DIRECT_NO_REPLY, int(self.OPCODE)])
        try:
            return head + struct.pack("<" + self.FORMAT, *self.fields())
        except struct.error as exc:
            raise ValueError(f"{type(self).__name__}: field out of range ({exc})") from exc

    def packet(self) -> bytes:
        """The Bluetooth packet (length prefix + telegram)."""
        return frame(self.encode())

    @property
    def reply_length(self) -> int:
        """Length of the success reply telegram in bytes."""
        return REPLY_TYPES[self.OPCODE].LENGTH


@dataclass(frozen=True)
class SetOutputState(Command):
    """SETOUTPUTSTATE: port (0-2 or 0xFF), power -100..100, mode bits, regulation, turn ratio,
    run state, tacho limit (degrees, 0 = run forever)."""

    OPCODE: ClassVar[Opcode] = Opcode.SET_OUTPUT_STATE
    FORMAT: ClassVar[str] = "BbBBbBI"
    port: int = 0
    power: int = 0
    mode: int = 0
    regulation: int = RegulationMode.IDLE
    turn_ratio: int = 0
    run_state: int = RunState.IDLE
    tacho_limit: int = 0

    @property
    def idempotent(self) -> bool:
        # A tacho limit counts from the moment the command arrives: repeating it re-arms the
        # limit, so only unlimited settings (speeds, stop) are safe to repeat.
        return self.tacho_limit == 0

    def fields(self) -> tuple:
        return (
            self.port,
            self.power,
            self.mode,
            self.regulation,
            self.turn_ratio,
            self.run_state,
            self.tacho_limit,
        )


@dataclass(frozen=True)
class SetInputMode(Command):
    """SETINPUTMODE: sensor port 0-3, sensor type, sensor mode."""

    OPCODE: ClassVar[Opcode] = Opcode.SET_INPUT_MODE
    FORMAT: ClassVar[str] = "BBB"
    port: int = 0
    sensor_type: int = SensorType.NO_SENSOR
    sensor_mode: int = SensorMode.RAW

    def fields(self) -> tuple:
        return (self.port, self.sensor_type, self.sensor_mode)


@dataclass(frozen=True)
class GetOutputState(Command):
    OPCODE: ClassVar[Opcode] = Opcode.GET_OUTPUT_STATE
    FORMAT: ClassVar[str] = "B"
    port: int = 0

    def fields(self) -> tuple:
        return (self.port,)


@dataclass(frozen=True)
class GetInputValues(Command):
    OPCODE: ClassVar[Opcode] = Opcode.GET_INPUT_VALUES
    FORMAT: ClassVar[str] = "B"
    port: int = 0

    def fields(self) -> tuple:
        return (self.port,)


@dataclass(frozen=True)
class ResetMotorPosition(Command):
    """RESETMOTORPOSITION: port, relative (True: block tacho count, False: rotation count)."""

    OPCODE: ClassVar[Opcode] = Opcode.RESET_MOTOR_POSITION
    FORMAT: ClassVar[str] = "BB"
    port: int = 0
    relative: bool = False

    @property
    def idempotent(self) -> bool:
        return False

    def fields(self) -> tuple:
        return (self.port, int(self.relative))


@dataclass(frozen=True)
class GetBatteryLevel(Command):
    OPCODE: ClassVar[Opcode] = Opcode.GET_BATTERY_LEVEL


@dataclass(frozen=True)
class KeepAlive(Command):
    OPCODE: ClassVar[Opcode] = Opcode.KEEP_ALIVE


@dataclass(frozen=True)
class LsGetStatus(Command):
    OPCODE: ClassVar[Opcode] = Opcode.LS_GET_STATUS
    FORMAT: ClassVar[str] = "B"
    port: int = 0

    def fields(self) -> tuple:
        return (self.port,)


@dataclass(frozen=True)
class LsWrite(Command):
    """LSWRITE: port, tx length, rx length, tx data (I2C address byte first)."""

    OPCODE: ClassVar[Opcode] = Opcode.LS_WRITE
    port: int = 0
    tx: bytes = b""
    rx_len: int = 0

    @property
    def idempotent(self) -> bool:
        return False  # queues an I2C transaction; callers retry whole transactions

    def encode(self) -> bytes:
        if not 0 <= len(self.tx) <= LS_MAX_BYTES or not 0 <= self.rx_len <= LS_MAX_BYTES:
            raise ValueError(
                f"LsWrite: tx {len(self.tx)} / rx {self.rx_len} bytes (at most {LS_MAX_BYTES})"
            )
        head = bytes([DIRECT_REPLY if self.reply else DIRECT_NO_REPLY, int(self.OPCODE)])
        return head + bytes([self.port, len(self.tx), self.rx_len]) + bytes(self.tx)


@dataclass(frozen=True)
class LsRead(Command):
    OPCODE: ClassVar[Opcode] = Opcode.LS_READ
    FORMAT: ClassVar[str] = "B"
    port: int = 0

    @property
    def idempotent(self) -> bool:
        return False  # consumes the brick's receive buffer

    def fields(self) -> tuple:
        return (self.port,)


COMMAND_TYPES: dict[int, type[Command]] = {
    c.OPCODE: c
    for c in (
        SetOutputState,
        SetInputMode,
        GetOutputState,
        GetInputValues,
        ResetMotorPosition,
        GetBatteryLevel,
        KeepAlive,
        LsGetStatus,
        LsWrite,
        LsRead,
    )
}


def parse_command(telegram: bytes) -> Command:
    """Decode a command telegram (the emulator's side).

    Raises:
        UnknownOpcodeError: the opcode is not one scenebot implements.
        IllegalSizeError: the payload length does not match the opcode.
        MalformedCommandError: too short, or a type byte other than 0x00 / 0x80.
    """
    if len(telegram) < 2:
        raise MalformedCommandError(f"command telegram of {len(telegram)} bytes")
    ctype, opcode = telegram[0], telegram[1]
    if ctype not in (DIRECT_REPLY, DIRECT_NO_REPLY):
        raise MalformedCommandError(f"command type 0x{ctype:02X} is not a direct command")
    cls = COMMAND_TYPES.get(opcode)
    if cls is None:
        raise UnknownOpcodeError(opcode)
    reply = ctype == DIRECT_REPLY
    body = telegram[2:]
    if cls is LsWrite:
        if len(body) < 3 or len(body) != 3 + body[1]:
            raise IllegalSizeError(opcode)
        return LsWrite(reply=reply, port=body[0], tx=bytes(body[3:]), rx_len=body[2])
    size = struct.calcsize("<" + cls.FORMAT)
    if len(body) != size:
        raise IllegalSizeError(opcode)
    values = struct.unpack("<" + cls.FORMAT, body)
    if cls is ResetMotorPosition:
        return ResetMotorPosition(reply=reply, port=values[0], relative=bool(values[1]))
    return cls(reply, *values)


# --------------------------------------------------------------------------- replies


@dataclass(frozen=True)
class Reply:
    """A success reply (status 0). Subclasses add the payload fields."""

    OPCODE: ClassVar[Opcode]
    FORMAT: ClassVar[str] = ""
    LENGTH: ClassVar[int] = 3

    def fields(self) -> tuple:
        return ()

    def encode(self, status: int = 0) -> bytes:
        """The reply telegram; a non-zero ``status`` zeroes the payload (firmware behaviour)."""
        payload = struct.pack("<" + self.FORMAT, *self.fields())
        if status:
            payload = bytes(len(payload))
        return bytes([REPLY, int(self.OPCODE), status]) + payload


@dataclass(frozen=True)
class StatusReply(Reply):
    """Reply without payload (SETOUTPUTSTATE, SETINPUTMODE, RESETMOTORPOSITION, LSWRITE)."""

    opcode: int = 0

    def encode(self, status: int = 0) -> bytes:
        return bytes([REPLY, self.opcode, status])


@dataclass(frozen=True)
class OutputState(Reply):
    """GETOUTPUTSTATE reply. Counts in degrees: ``tacho_count`` since the last motor command
    (what the tacho limit counts), ``block_tacho_count`` since the last relative reset,
    ``rotation_count`` since the last absolute reset (power-on)."""

    OPCODE: ClassVar[Opcode] = Opcode.GET_OUTPUT_STATE
    FORMAT: ClassVar[str] = "BbBBbBIiii"
    LENGTH: ClassVar[int] = 25
    port: int = 0
    power: int = 0
    mode: int = 0
    regulation: int = 0
    turn_ratio: int = 0
    run_state: int = 0
    tacho_limit: int = 0
    tacho_count: int = 0
    block_tacho_count: int = 0
    rotation_count: int = 0

    def fields(self) -> tuple:
        return (
            self.port,
            self.power,
            self.mode,
            self.regulation,
            self.turn_ratio,
            self.run_state,
            self.tacho_limit,
            self.tacho_count,
            self.block_tacho_count,
            self.rotation_count,
        )

    @property
    def running(self) -> bool:
        """Motor powered and not idle."""
        return bool(self.mode & OutputMode.MOTORON) and self.run_state != RunState.IDLE


@dataclass(frozen=True)
class InputValues(Reply):
    """GETINPUTVALUES reply."""

    OPCODE: ClassVar[Opcode] = Opcode.GET_INPUT_VALUES
    FORMAT: ClassVar[str] = "B??BBHHhh"
    LENGTH: ClassVar[int] = 16
    port: int = 0
    valid: bool = False
    calibrated: bool = False
    sensor_type: int = 0
    sensor_mode: int = 0
    raw: int = 0
    normalized: int = 0
    scaled: int = 0
    calibrated_value: int = 0

    def fields(self) -> tuple:
        return (
            self.port,
            self.valid,
            self.calibrated,
            self.sensor_type,
            self.sensor_mode,
            self.raw,
            self.normalized,
            self.scaled,
            self.calibrated_value,
        )


@dataclass(frozen=True)
class BatteryLevel(Reply):
    OPCODE: ClassVar[Opcode] = Opcode.GET_BATTERY_LEVEL
    FORMAT: ClassVar[str] = "H"
    LENGTH: ClassVar[int] = 5
    millivolts: int = 0

    def fields(self) -> tuple:
        return (self.millivolts,)


@dataclass(frozen=True)
class KeepAliveReply(Reply):
    """KEEPALIVE reply: the brick's current sleep time limit in ms (0 = never sleeps)."""

    OPCODE: ClassVar[Opcode] = Opcode.KEEP_ALIVE
    FORMAT: ClassVar[str] = "I"
    LENGTH: ClassVar[int] = 7
    sleep_limit_ms: int = 0

    def fields(self) -> tuple:
        return (self.sleep_limit_ms,)


@dataclass(frozen=True)
class LsStatus(Reply):
    OPCODE: ClassVar[Opcode] = Opcode.LS_GET_STATUS
    FORMAT: ClassVar[str] = "B"
    LENGTH: ClassVar[int] = 4
    bytes_ready: int = 0

    def fields(self) -> tuple:
        return (self.bytes_ready,)


@dataclass(frozen=True)
class LsReadReply(Reply):
    """LSREAD reply: always 20 bytes; ``data`` is the first ``bytes_read`` of the 16."""

    OPCODE: ClassVar[Opcode] = Opcode.LS_READ
    LENGTH: ClassVar[int] = 20
    data: bytes = b""

    def encode(self, status: int = 0) -> bytes:
        data = b"" if status else bytes(self.data)
        if len(data) > LS_READ_DATA_BYTES:
            raise ValueError(f"LsReadReply: {len(data)} bytes (at most {LS_READ_DATA_BYTES})")
        padded = data + bytes(LS_READ_DATA_BYTES - len(data))
        return bytes([REPLY, int(self.OPCODE), status, len(data)]) + padded


class _Simple:
    LENGTH = 3


REPLY_TYPES: dict[int, type[Reply] | type[_Simple]] = {
    Opcode.SET_OUTPUT_STATE: _Simple,
    Opcode.SET_INPUT_MODE: _Simple,
    Opcode.RESET_MOTOR_POSITION: _Simple,
    Opcode.LS_WRITE: _Simple,
    Opcode.GET_OUTPUT_STATE: OutputState,
    Opcode.GET_INPUT_VALUES: InputValues,
    Opcode.GET_BATTERY_LEVEL: BatteryLevel,
    Opcode.KEEP_ALIVE: KeepAliveReply,
    Opcode.LS_GET_STATUS: LsStatus,
    Opcode.LS_READ: LsReadReply,
}


def parse_reply(telegram: bytes, expected_opcode: int | None = None) -> Reply:
    """Decode and validate a reply telegram (without the Bluetooth length prefix).

    Args:
        telegram: the reply bytes ``[0x02, opcode, status, payload...]``.
        expected_opcode: if given, the opcode the reply must echo.

    Returns:
        The typed reply (status 0).

    Raises:
        MalformedReplyError: wrong type byte, unexpected or unknown opcode, wrong length, or
            an LSREAD byte count above 16.
        DirectCommandError: (a subclass per status code) the brick reported an error.
    """
    if len(telegram) < 3:
        raise MalformedReplyError(f"reply of {len(telegram)} bytes (at least 3 expected)")
    rtype, opcode, status = telegram[0], telegram[1], telegram[2]
    if rtype != REPLY:
        raise MalformedReplyError(f"reply type byte 0x{rtype:02X} (expected 0x02)")
    if expected_opcode is not None and opcode != expected_opcode:
        raise MalformedReplyError(
            f"reply echoes opcode 0x{opcode:02X}, expected 0x{expected_opcode:02X}"
        )
    cls = REPLY_TYPES.get(opcode)
    if cls is None:
        raise MalformedReplyError(f"reply for unknown opcode 0x{opcode:02X}")
    # Error replies are accepted at the full length (firmware) or cut to the status byte.
    if status != 0 and len(telegram) in (3, cls.LENGTH):
        raise status_error(opcode, status)
    if len(telegram) != cls.LENGTH:
        raise MalformedReplyError(
            f"reply to opcode 0x{opcode:02X} has {len(telegram)} bytes, expected {cls.LENGTH}"
        )
    if cls is _Simple:
        return StatusReply(opcode=opcode)
    body = telegram[3:]
    if cls is LsReadReply:
        n = body[0]
        if n > LS_READ_DATA_BYTES:
            raise MalformedReplyError(f"LSREAD reports {n} bytes read (at most 16)")
        return LsReadReply(data=bytes(body[1 : 1 + n]))
    assert issubclass(cls, Reply)
    return cls(*struct.unpack("<" + cls.FORMAT, body))
