"""Wire-level tests of the NXT direct-command telegrams: exact bytes both ways (BDK layouts)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from scenebot.robot.nxt import protocol as p


def h(s: str) -> bytes:
    return bytes.fromhex(s)


# (command, exact Bluetooth packet: 2-byte LE length + telegram)
COMMANDS = [
    (
        p.SetOutputState(
            port=1,
            power=-75,
            mode=0x07,
            regulation=1,
            turn_ratio=0,
            run_state=0x20,
            tacho_limit=360,
        ),
        "0c00 00 04 01 b5 07 01 00 20 68010000",
    ),
    (
        p.SetOutputState(reply=False, port=0xFF, power=0, mode=0, regulation=0, run_state=0),
        "0c00 80 04 ff 00 00 00 00 00 00000000",
    ),
    (
        p.SetOutputState(
            port=2, power=100, mode=1, turn_ratio=-100, run_state=0x10, tacho_limit=0x01020304
        ),
        "0c00 00 04 02 64 01 00 9c 10 04030201",
    ),
    (p.SetInputMode(port=3, sensor_type=0x0B, sensor_mode=0x00), "0500 00 05 03 0b 00"),
    (p.SetInputMode(port=0, sensor_type=0x01, sensor_mode=0x20), "0500 00 05 00 01 20"),
    (p.GetOutputState(port=2), "0300 00 06 02"),
    (p.GetInputValues(port=1), "0300 00 07 01"),
    (p.ResetMotorPosition(port=1, relative=True), "0400 00 0a 01 01"),
    (p.ResetMotorPosition(port=0, relative=False), "0400 00 0a 00 00"),
    (p.GetBatteryLevel(), "0200 00 0b"),
    (p.KeepAlive(), "0200 00 0d"),
    (p.KeepAlive(reply=False), "0200 80 0d"),
    (p.LsGetStatus(port=3), "0300 00 0e 03"),
    (p.LsWrite(port=3, tx=b"\x02\x42", rx_len=1), "0700 00 0f 03 02 01 02 42"),
    (p.LsWrite(port=2, tx=b"\x02\x41\x02", rx_len=0), "0800 00 0f 02 03 00 02 41 02"),
    (p.LsRead(port=3), "0300 00 10 03"),
]


@pytest.mark.parametrize(("cmd", "packet"), COMMANDS)
def test_command_bytes_and_roundtrip(cmd, packet):
    assert cmd.packet() == h(packet)
    assert p.parse_command(cmd.encode()) == cmd


# (telegram, parsed reply)
REPLIES = [
    ("02 04 00", p.StatusReply(opcode=0x04)),
    ("02 05 00", p.StatusReply(opcode=0x05)),
    ("02 0a 00", p.StatusReply(opcode=0x0A)),
    ("02 0f 00", p.StatusReply(opcode=0x0F)),
    (
        "02 06 00 01 b5 07 01 00 20 68010000 fbffffff 2c010000 d2040000",
        p.OutputState(
            port=1,
            power=-75,
            mode=7,
            regulation=1,
            turn_ratio=0,
            run_state=0x20,
            tacho_limit=360,
            tacho_count=-5,
            block_tacho_count=300,
            rotation_count=1234,
        ),
    ),
    (
        "02 07 00 00 01 00 01 20 b700 b700 0100 0100",
        p.InputValues(
            port=0,
            valid=True,
            calibrated=False,
            sensor_type=1,
            sensor_mode=0x20,
            raw=183,
            normalized=183,
            scaled=1,
            calibrated_value=1,
        ),
    ),
    (
        "02 07 00 02 00 00 00 00 0000 0000 ffff 0080",
        p.InputValues(port=2, sensor_type=0, scaled=-1, calibrated_value=-32768),
    ),
    ("02 0b 00 a41f", p.BatteryLevel(millivolts=8100)),
    ("02 0d 00 c0270900", p.KeepAliveReply(sleep_limit_ms=600000)),
    ("02 0e 00 02", p.LsStatus(bytes_ready=2)),
    ("02 10 00 01 2a" + "00" * 15, p.LsReadReply(data=b"\x2a")),
    ("02 10 00 02 5a 01" + "00" * 14, p.LsReadReply(data=b"\x5a\x01")),
    ("02 10 00 00" + "00" * 16, p.LsReadReply(data=b"")),
]


@pytest.mark.parametrize(("telegram", "reply"), REPLIES)
def test_reply_bytes_and_roundtrip(telegram, reply):
    raw = h(telegram)
    assert p.parse_reply(raw) == reply
    assert reply.encode() == raw


def test_lsread_reply_is_always_20_bytes():
    for n in range(17):
        assert len(p.LsReadReply(data=bytes(range(n))).encode()) == 20
    with pytest.raises(p.MalformedReplyError, match="at most 16"):
        p.parse_reply(h("02 10 00 11") + bytes(16))


ALL_STATUSES = [
    (0x20, p.PendingTransactionError),
    (0x40, p.MailboxEmptyError),
    (0xBD, p.RequestFailedError),
    (0xBE, p.UnknownOpcodeError),
    (0xBF, p.InsanePacketError),
    (0xC0, p.OutOfRangeError),
    (0xDD, p.BusError),
    (0xDE, p.NoFreeMemoryError),
    (0xDF, p.ChannelInvalidError),
    (0xE0, p.ChannelBusyError),
    (0xEC, p.NoActiveProgramError),
    (0xED, p.IllegalSizeError),
    (0xEE, p.IllegalMailboxError),
    (0xEF, p.InvalidFieldError),
    (0xF0, p.BadIoError),
    (0xFB, p.InsufficientMemoryError),
    (0xFF, p.BadArgumentsError),
]


@pytest.mark.parametrize(("status", "cls"), ALL_STATUSES)
def test_error_status_becomes_typed_error(status, cls):
    # full-length error reply (payload zeroed, as the firmware sends it) and status-only form
    full = bytes([0x02, 0x10, status]) + bytes(17)
    assert p.LsReadReply(data=b"\x01").encode(status) == full
    for raw in (full, bytes([0x02, 0x10, status])):
        with pytest.raises(cls) as info:
            p.parse_reply(raw, 0x10)
        assert info.value.status == status and info.value.opcode == 0x10
        assert f"0x{status:02X}" in str(info.value)
    assert p.StatusReply(opcode=0x04).encode(status) == bytes([2, 4, status])


def test_undocumented_status_is_base_error():
    with pytest.raises(p.DirectCommandError) as info:
        p.parse_reply(h("02 0b 77 0000"))
    assert type(info.value) is p.DirectCommandError and info.value.status == 0x77


@pytest.mark.parametrize(
    ("telegram", "match"),
    [
        ("", "0 bytes"),
        ("02 04", "2 bytes"),
        ("03 04 00", "type byte"),
        ("02 05 00", "expected 0x04"),
        ("02 99 00", "unknown opcode"),
        ("02 04 00 00", "expected 3"),
        ("02 0b 00 a4", "expected 5"),
        ("02 06 00" + "00" * 21, "expected 25"),
    ],
)
def test_malformed_replies(telegram, match):
    with pytest.raises(p.MalformedReplyError, match=match):
        p.parse_reply(h(telegram), 0x04 if "expected 0x04" in match else None)


def test_command_field_range_and_size_errors():
    with pytest.raises(ValueError, match="out of range"):
        p.SetOutputState(power=200).encode()
    with pytest.raises(ValueError, match="at most 16"):
        p.LsWrite(tx=bytes(17)).encode()
    with pytest.raises(p.IllegalSizeError):
        p.parse_command(h("00 06 01 02"))
    with pytest.raises(p.IllegalSizeError):
        p.parse_command(h("00 0f 03 05 01 02 42"))  # says 5 tx bytes, has 2
    with pytest.raises(p.UnknownOpcodeError):
        p.parse_command(h("00 55"))


def test_idempotence_flags():
    assert p.GetOutputState().idempotent and p.KeepAlive().idempotent
    assert p.SetOutputState(power=50, tacho_limit=0).idempotent
    assert not p.SetOutputState(power=50, tacho_limit=90).idempotent
    assert not p.LsWrite().idempotent and not p.LsRead().idempotent
    assert not p.ResetMotorPosition().idempotent


def test_frame_decoder_reassembles_split_packets():
    stream = p.KeepAliveReply(sleep_limit_ms=5).encode()
    stream = p.frame(stream) + p.frame(p.StatusReply(opcode=4).encode())
    dec = p.FrameDecoder()
    out = []
    for b in stream:
        out += dec.feed(bytes([b]))
    assert out == [h("02 0d 00 05000000"), h("02 04 00")]
    assert dec.pending == 0
    with pytest.raises(p.FramingError):
        dec.feed(h("0000"))
    with pytest.raises(p.FramingError):
        dec.feed(h("4100"))
    assert dec.pending == 0
    with pytest.raises(p.FramingError):
        p.frame(bytes(65))


@settings(max_examples=400, deadline=None)
@given(st.binary(max_size=40), st.one_of(st.none(), st.integers(0, 255)))
def test_fuzz_parse_reply_only_typed_errors(data, expected):
    try:
        reply = p.parse_reply(data, expected)
    except p.ProtocolError:
        return
    assert isinstance(reply, p.Reply)
    assert data[0] == 0x02 and data[2] == 0
    if expected is not None:
        assert data[1] == expected
    # encoding is canonical (booleans as 0/1, LSREAD padding zeroed): a fixed point
    assert p.parse_reply(reply.encode(), expected) == reply
    if not isinstance(reply, p.LsReadReply | p.InputValues):
        assert reply.encode() == data


@settings(max_examples=300, deadline=None)
@given(
    st.sampled_from([0x04, 0x05, 0x06, 0x07, 0x0A, 0x0B, 0x0D, 0x0E, 0x0F, 0x10]),
    st.integers(0, 255),
    st.binary(max_size=30),
)
def test_fuzz_reply_like_telegrams(opcode, status, payload):
    """Telegrams that look like replies (right type byte, real opcode) stress the length and
    status paths, which random bytes rarely reach."""
    data = bytes([0x02, opcode, status]) + payload
    try:
        p.parse_reply(data, opcode)
    except p.DirectCommandError as exc:
        assert status != 0 and exc.status == status
    except p.MalformedReplyError:
        pass


@settings(max_examples=300, deadline=None)
@given(st.lists(st.binary(max_size=12), max_size=8))
def test_fuzz_frame_decoder(chunks):
    dec = p.FrameDecoder()
    for c in chunks:
        try:
            for tg in dec.feed(c):
                assert 1 <= len(tg) <= p.MAX_TELEGRAM
        except p.FramingError:
            assert dec.pending == 0


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=24))
def test_fuzz_parse_command_only_typed_errors(data):
    try:
        cmd = p.parse_command(data)
    except p.ProtocolError:
        return
    assert p.parse_command(cmd.encode()) == cmd
    if not isinstance(cmd, p.ResetMotorPosition):  # any non-zero byte means "relative"
        assert cmd.encode() == data
