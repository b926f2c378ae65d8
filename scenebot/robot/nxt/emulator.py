"""A LEGO NXT brick emulator on a pseudo-terminal, backed by the simulator's physics.

The emulator opens a pty pair (``os.openpty``), puts it in raw mode and exposes a stable path
(a symlink to the pty slave, like ``/dev/rfcomm0``) that the driver opens with pyserial exactly
as it would open a real Bluetooth serial port. It answers the direct-command protocol of
:mod:`scenebot.robot.nxt.protocol` byte-exactly:

* three motor ports with power, mode, regulation, run state, tacho limit and the three
  counters (tacho count since the last motor command, block tacho count, rotation count);
  the two wheel ports drive ``world.set_wheel_speeds`` (power p -> p/100 *
  ``max_wheel_speed_deg_s``) and count ``world.tacho_deg`` (which stops while a wheel is
  blocked, so stalls are real); a tacho limit stops the motor when reached;
* four sensor ports with type/mode; touch switches read ``world.bumpers()``; I2C devices at
  address 0x02 on low-speed ports: the LEGO ultrasonic (needs ``LOWSPEED_9V``; register 0x41
  command, 0x42 distance from ``world.ultrasonic_cm()``) and the HiTechnic compass
  (0x42 = h / 2, 0x43 = h mod 2, h clockwise, from ``world.compass_deg()``); a port answers
  0xE0 for ``i2c_pending_s`` after SETINPUTMODE and 0x20 while a transaction is in progress;
* the camera port: powering it for at least ``camera_min_pulse_s`` renders the photo at the
  current pose (``world.render_jpeg``) and uploads it into the inbox in chunks;
* KEEPALIVE resets the sleep timer (motor commands do not); after ``sleep_limit_s`` without
  one the brick switches off (motors stop, the port disappears for good); motors keep
  running when the link drops.

Faults (:class:`~scenebot.robot.nxt.config.FaultConfig`): dropped reply, lost command, late
reply (the link stalls: replies stay in order), split frames, brick reboot (motors stop,
counters reset, sensor modes lost) and port vanishing.

Brick-internal times (pulses, I2C delays, physics) run on simulated time (``time_scale``
simulated seconds per wall second); link events (late replies, uploads, sleep) on wall time.
"""

from __future__ import annotations

import contextlib
import heapq
import itertools
import logging
import os
import random
import select
import tempfile
import threading
import time
import tty
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

from scenebot.robot.nxt.config import EmulatorConfig, NxtConfig, motor_index, sensor_index
from scenebot.robot.nxt.protocol import (
    ALL_MOTORS,
    STATUS_ERRORS,
    BatteryLevel,
    Command,
    FrameDecoder,
    FramingError,
    GetBatteryLevel,
    GetInputValues,
    GetOutputState,
    InputValues,
    KeepAlive,
    KeepAliveReply,
    LsGetStatus,
    LsRead,
    LsReadReply,
    LsStatus,
    LsWrite,
    OutputMode,
    OutputState,
    ProtocolError,
    Reply,
    ResetMotorPosition,
    RunState,
    SensorMode,
    SensorType,
    SetInputMode,
    SetOutputState,
    StatusReply,
    frame,
    parse_command,
)

log = logging.getLogger(__name__)

OK = 0x00
PENDING = 0x20
BUS_ERROR = 0xDD
CHANNEL_INVALID = 0xDF
CHANNEL_BUSY = 0xE0
OUT_OF_RANGE = 0xC0
I2C_ADDRESS = 0x02


class World(Protocol):
    """The simulator API the emulator drives (``scenebot.sim.world.SimWorld``)."""

    t: float

    def set_wheel_speeds(self, left_deg_s: float, right_deg_s: float) -> None: ...

    def step(self, dt: float) -> None: ...

    @property
    def tacho_deg(self) -> tuple[float, float]: ...

    def bumpers(self) -> tuple[bool, bool]: ...

    def ultrasonic_cm(self) -> int: ...

    def compass_deg(self) -> float: ...

    def render_jpeg(self, path: Path) -> None: ...


@dataclass
class Motor:
    power: int = 0
    mode: int = 0
    regulation: int = 0
    turn_ratio: int = 0
    run_state: int = RunState.IDLE
    tacho_limit: int = 0
    tacho_count: float = 0.0
    block_tacho_count: float = 0.0
    rotation_count: float = 0.0

    @property
    def powered(self) -> bool:
        return bool(self.mode & OutputMode.MOTORON) and self.run_state != RunState.IDLE

    def output_state(self, port: int) -> OutputState:
        return OutputState(
            port=port,
            power=self.power,
            mode=self.mode,
            regulation=self.regulation,
            turn_ratio=self.turn_ratio,
            run_state=self.run_state,
            tacho_limit=self.tacho_limit,
            tacho_count=round(self.tacho_count),
            block_tacho_count=round(self.block_tacho_count),
            rotation_count=round(self.rotation_count),
        )


@dataclass
class SensorPort:
    sensor_type: int = SensorType.NO_SENSOR
    sensor_mode: int = SensorMode.RAW
    mode_set_at: float = -1e9
    busy_until: float = -1e9
    rx: bytes | None = None
    bus_error: bool = False


@dataclass
class I2CDevice:
    """Register file of an I2C sensor; ``live`` supplies the measurement registers."""

    registers: dict[int, int] = field(default_factory=dict)
    needs_9v: bool = False
    live: Callable[[I2CDevice], dict[int, int]] | None = None

    def read(self, reg: int, n: int) -> bytes:
        regs = dict(self.registers)
        if self.live is not None:
            regs.update(self.live(self))
        return bytes(regs.get(r, 0) & 0xFF for r in range(reg, reg + n))

    def write(self, reg: int, data: bytes) -> None:
        for i, b in enumerate(data):
            self.registers[reg + i] = b


def _text_regs(start: int, text: bytes) -> dict[int, int]:
    return {start + i: b for i, b in enumerate(text.ljust(8, b"\0")[:8])}


class NxtEmulator:
    """The brick on a pty. Use as a context manager or call :meth:`start` / :meth:`close`.

    Args:
        world: the simulated world (see :class:`World`).
        cfg: emulator settings (inbox, timing, faults).
        wiring: the robot's port wiring and wheel speed scale (an :class:`NxtConfig`).
        max_wheel_speed_deg_s: wheel speed at power 100; default ``world.params``.
    """

    def __init__(
        self,
        world: World,
        cfg: EmulatorConfig,
        wiring: NxtConfig | None = None,
        max_wheel_speed_deg_s: float | None = None,
    ):
        self.world, self.cfg = world, cfg
        self.wiring = wiring or NxtConfig()
        if max_wheel_speed_deg_s is None:
            max_wheel_speed_deg_s = float(world.params.max_wheel_speed_deg_s)  # type: ignore[attr-defined]
        self.max_speed = max_wheel_speed_deg_s
        self.inbox = Path(cfg.inbox)
        if not self.inbox.is_dir():
            raise FileNotFoundError(
                f"emulator inbox folder {self.inbox} does not exist: create it (it plays the "
                "Wi-Fi SD card's upload folder, nxt.camera.inbox)"
            )
        w = self.wiring
        self.left_port = motor_index(w.left_motor)
        self.right_port = motor_index(w.right_motor)
        self.camera_port = motor_index(w.camera.port)
        self.wheel_sign = -1 if w.reverse_motors else 1
        self.front_port = sensor_index(w.bumper_front)
        self.rear_port = sensor_index(w.bumper_rear)
        self.us_port = sensor_index(w.ultrasonic)
        self.compass_port = sensor_index(w.compass)
        self._rng = random.Random(cfg.faults.seed)
        self._tmp = Path(tempfile.mkdtemp(prefix="nxt-emu-"))
        self.link_path = Path(cfg.link_path) if cfg.link_path else self._tmp / "rfcomm-emu"
        self._master: int | None = None
        self._slave: int | None = None
        self.pty_path: str | None = None
        self._decoder = FrameDecoder()
        self._events: list[tuple[float, int, Callable[[], None]]] = []
        self._seq = itertools.count()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._photo_seq = 0
        # records for tests / diagnostics
        self.commands: list[Command] = []
        self.command_count = 0
        self.photos: list[Path] = []
        self.uploads_pending = 0
        self.reboots = 0
        self.vanished = 0
        self.asleep = False
        self.framing_errors = 0
        self.render_errors: list[Exception] = []
        self.error = None
        self._reset_brick()

    # ------------------------------------------------------------------ lifecycle

    @property
    def port_path(self) -> str:
        """The path the driver opens (stable across port vanishing)."""
        return str(self.link_path)

    def start(self) -> NxtEmulator:
        self._open_pty()
        self._wall0 = time.monotonic()
        self._sim0 = float(self.world.t)
        self._last_keepalive = self._wall0
        self._thread = threading.Thread(target=self._run, name="nxt-emulator", daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        """Stop the loop, flush pending uploads, remove the pty and the link."""
        if self._thread is not None:
            self._stop.set()
            self._thread.join(timeout=5.0)
            self._thread = None
        # finish uploads so no photo is lost
        for _, _, fn in sorted(self._events):
            if getattr(fn, "is_upload", False):
                fn()
        self._events.clear()
        self._close_pty()
        with contextlib.suppress(OSError):
            for p in self._tmp.iterdir():
                p.unlink()
            self._tmp.rmdir()

    def __enter__(self) -> NxtEmulator:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()

    def _open_pty(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)
        self._master, self._slave = master, slave
        self.pty_path = os.ttyname(slave)
        tmp_link = self.link_path.with_name(self.link_path.name + ".new")
        with contextlib.suppress(FileNotFoundError):
            tmp_link.unlink()
        os.symlink(self.pty_path, tmp_link)
        os.replace(tmp_link, self.link_path)  # atomic repoint
        self._decoder.clear()
        self._tx_free_at = 0.0

    def _close_pty(self) -> None:
        with contextlib.suppress(FileNotFoundError):
            if self.link_path.is_symlink():
                self.link_path.unlink()
        for fd in (self._master, self._slave):
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._master = self._slave = None

    # ------------------------------------------------------------------ state

    def _reset_brick(self) -> None:
        """Power-on state: motors idle, counters 0, sensor ports without type."""
        self.motors = [Motor() for _ in range(3)]
        self.sensors = [SensorPort() for _ in range(4)]
        self.devices: dict[int, I2CDevice] = {
            self.us_port: I2CDevice(
                registers={
                    **_text_regs(0x00, b"V1.0"),
                    **_text_regs(0x08, b"LEGO"),
                    **_text_regs(0x10, b"Sonar"),
                    0x41: 0x02,
                },
                needs_9v=True,
                live=self._ultrasonic_regs,
            ),
            self.compass_port: I2CDevice(
                registers={
                    **_text_regs(0x00, b"\xfdV1.23"),
                    **_text_regs(0x08, b"HiTechnc"),
                    **_text_regs(0x10, b"Compass"),
                    0x41: 0x00,
                },
                live=self._compass_regs,
            ),
        }
        self._pulse_start: float | None = None
        self._pulse_fired = False
        if hasattr(self, "world"):
            self.world.set_wheel_speeds(0.0, 0.0)

    def truth_record(self) -> dict:
        """The world's true pose record (evaluation and logging only), read under the lock."""
        with self._lock:
            return self.world.truth_record()  # type: ignore[attr-defined]

    def sim_now(self) -> float:
        return float(self.world.t)

    def motors_running(self) -> bool:
        """Whether any output is powered with non-zero power."""
        with self._lock:
            return any(m.powered and m.power != 0 for m in self.motors)

    def _ultrasonic_regs(self, dev: I2CDevice) -> dict[int, int]:
        if dev.registers.get(0x41, 0) != 0x02:  # not continuous: last value stays
            return {}
        cm = int(self.world.ultrasonic_cm())
        dev.registers[0x42] = max(0, min(255, cm))
        return {0x42: dev.registers[0x42]}

    def _compass_regs(self, dev: I2CDevice) -> dict[int, int]:
        h = round(360.0 - float(self.world.compass_deg())) % 360  # the sensor counts clockwise
        return {0x42: h // 2, 0x43: h % 2, 0x44: h & 0xFF, 0x45: h >> 8}

    # ------------------------------------------------------------------ loop

    def _schedule(self, delay_s: float, fn: Callable[[], None]) -> None:
        heapq.heappush(self._events, (time.monotonic() + delay_s, next(self._seq), fn))

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                timeout = 0.005
                if self._events:
                    timeout = max(0.0, min(timeout, self._events[0][0] - time.monotonic()))
                data = b""
                master = self._master
                if master is not None:
                    try:
                        r, _, _ = select.select([master], [], [], timeout)
                        if r:
                            data = os.read(master, 4096)
                    except OSError:
                        data = b""
                else:
                    time.sleep(timeout)
                with self._lock:
                    self._advance_physics()
                    self._check_sleep()
                    if data:
                        try:
                            telegrams = self._decoder.feed(data)
                        except FramingError:
                            self.framing_errors += 1
                            telegrams = []
                        for tg in telegrams:
                            self._on_telegram(tg)
                    now = time.monotonic()
                    while self._events and self._events[0][0] <= now:
                        _, _, fn = heapq.heappop(self._events)
                        fn()
        except Exception as exc:  # surface emulator crashes to tests
            self.error = exc
            log.exception("NXT emulator crashed")
            raise

    def _advance_physics(self) -> None:
        target = self._sim0 + (time.monotonic() - self._wall0) * self.cfg.time_scale
        dt = self.cfg.physics_dt_s
        steps = 0
        while self.world.t + dt <= target + 1e-9 and steps < 200:
            self._physics_step(dt)
            steps += 1
        if steps == 200:  # fell behind (slow render): drop the backlog, do not race it
            self._sim0 -= target - self.world.t
        self._camera_check()

    def _physics_step(self, dt: float) -> None:
        """Advance the world by ``dt``; a motor reaching its tacho limit stops exactly there
        (the step is split at the moment the first running motor would reach its limit),
        as the firmware's position regulation does."""
        ml, mr = self.motors[self.left_port], self.motors[self.right_port]

        def speed(m: Motor) -> float:
            return self.wheel_sign * m.power / 100.0 * self.max_speed if m.powered else 0.0

        left = dt
        while left > 1e-9:
            h = left
            for m in (ml, mr):
                v = abs(speed(m))
                if m.tacho_limit and v > 0:
                    h = min(h, max((m.tacho_limit - abs(m.tacho_count)) / v, 1e-4))
            before = self.world.tacho_deg
            self.world.set_wheel_speeds(speed(ml), speed(mr))
            self.world.step(h)
            left -= h
            after = self.world.tacho_deg
            for m, d in ((ml, after[0] - before[0]), (mr, after[1] - before[1])):
                d *= self.wheel_sign
                m.tacho_count += d
                m.block_tacho_count += d
                m.rotation_count += d
                if m.powered and m.tacho_limit and abs(m.tacho_count) >= m.tacho_limit - 1e-6:
                    m.power, m.run_state = 0, RunState.IDLE  # limit reached: brake and idle
        self.world.set_wheel_speeds(speed(ml), speed(mr))

    def _camera_check(self) -> None:
        m = self.motors[self.camera_port]
        on = m.powered and m.power != 0
        t = self.sim_now()
        if not on:
            self._pulse_start, self._pulse_fired = None, False
            return
        if self._pulse_start is None:
            self._pulse_start = t
        if not self._pulse_fired and t - self._pulse_start >= self.cfg.camera_min_pulse_s - 1e-9:
            self._pulse_fired = True
            try:
                self._take_photo()
            except Exception as exc:  # a camera failure must not take the brick down
                self.render_errors.append(exc)
                log.exception("emulated camera: rendering the photo failed")

    def _take_photo(self) -> None:
        self._photo_seq += 1
        while True:
            name = f"IMG_{self._photo_seq:04d}.JPG"
            if not (self.inbox / name).exists():
                break
            self._photo_seq += 1
        tmp = self._tmp / name
        self.world.render_jpeg(tmp)
        data = tmp.read_bytes()
        tmp.unlink()
        dest = self.inbox / name
        self.photos.append(dest)
        n = self.cfg.upload_chunk_bytes
        chunks = [data[i : i + n] for i in range(0, len(data), n)]
        self.uploads_pending += 1
        for k, chunk in enumerate(chunks):
            last = k == len(chunks) - 1

            def write(chunk=chunk, last=last) -> None:
                with open(dest, "ab") as fh:
                    fh.write(chunk)
                if last:
                    self.uploads_pending -= 1

            write.is_upload = True  # type: ignore[attr-defined]
            self._schedule(self.cfg.shutter_delay_s + k * self.cfg.upload_chunk_interval_s, write)

    def _check_sleep(self) -> None:
        limit = self.cfg.sleep_limit_s
        if self.asleep or limit <= 0 or time.monotonic() - self._last_keepalive < limit:
            return
        log.warning("emulated brick: sleep timer expired, switching off")
        self.asleep = True
        self._reset_brick()
        self._close_pty()

    # ------------------------------------------------------------------ protocol

    def _send(self, reply: bytes, delay_s: float = 0.0) -> None:
        """Queue a reply on the link. The link is FIFO: a late reply delays the ones after
        it (as a stalled Bluetooth link does)."""
        if self._master is None:
            return
        packet = frame(reply)
        f = self.cfg.faults
        now = time.monotonic()
        start = max(now + delay_s, self._tx_free_at)
        pieces = [packet]
        if f.split_frames:
            pieces = [packet[i : i + 3] for i in range(0, len(packet), 3)]
        for k, piece in enumerate(pieces):
            t = start + (k * f.split_gap_s if f.split_frames else 0.0)
            if t <= now:
                self._write(piece)
            else:
                self._schedule(t - now, lambda p=piece: self._write(p))
            self._tx_free_at = t

    def _write(self, data: bytes) -> None:
        if self._master is None:
            return
        with contextlib.suppress(OSError):
            os.write(self._master, data)

    def _on_telegram(self, telegram: bytes) -> None:
        index = self.command_count
        self.command_count += 1
        f = self.cfg.faults
        if index in f.vanish_at:
            self._vanish()
            return
        if index in f.drop_command_at:
            return
        if index in f.reboot_at:
            self.reboot()
        try:
            cmd = parse_command(telegram)
        except ProtocolError as exc:
            status = getattr(exc, "status", 0xBF)
            if len(telegram) >= 2 and telegram[0] == 0x00:
                self._send(bytes([0x02, telegram[1], status]))
            return
        self.commands.append(cmd)
        status, reply = self._execute(cmd)
        if not cmd.reply:
            return
        data = reply.encode(status)
        if index in f.drop_reply_at or (
            f.drop_reply_prob and self._rng.random() < f.drop_reply_prob
        ):
            return
        self._send(data, f.late_reply_s if index in f.late_reply_at else 0.0)

    def reboot(self) -> None:
        """Brick reboot: motors stop, counters reset, sensor modes lost (link kept)."""
        self.reboots += 1
        self._reset_brick()

    def _vanish(self) -> None:
        """The port disappears (link drop); the motors keep running."""
        self.vanished += 1
        self._close_pty()
        if self.cfg.faults.vanish_for_s is not None:
            self._schedule(self.cfg.faults.vanish_for_s, self._open_pty)

    def _execute(self, cmd: Command) -> tuple[int, Reply]:
        t = self.sim_now()
        if isinstance(cmd, SetOutputState):
            ports = range(3) if cmd.port == ALL_MOTORS else [cmd.port]
            if (cmd.port > 2 and cmd.port != ALL_MOTORS) or not -100 <= cmd.power <= 100:
                return OUT_OF_RANGE, StatusReply(opcode=cmd.OPCODE)
            for p in ports:
                m = self.motors[p]
                m.power, m.mode, m.regulation = cmd.power, cmd.mode, cmd.regulation
                m.turn_ratio, m.run_state, m.tacho_limit = (
                    cmd.turn_ratio,
                    cmd.run_state,
                    cmd.tacho_limit,
                )
                m.tacho_count = 0.0  # the tacho limit counts from this command
            self._camera_check()
            return OK, StatusReply(opcode=cmd.OPCODE)
        if isinstance(cmd, GetOutputState):
            if cmd.port > 2:
                return OUT_OF_RANGE, OutputState(port=cmd.port)
            return OK, self.motors[cmd.port].output_state(cmd.port)
        if isinstance(cmd, ResetMotorPosition):
            if cmd.port > 2:
                return OUT_OF_RANGE, StatusReply(opcode=cmd.OPCODE)
            m = self.motors[cmd.port]
            if cmd.relative:
                m.block_tacho_count = 0.0
            else:
                m.rotation_count = 0.0
            return OK, StatusReply(opcode=cmd.OPCODE)
        if isinstance(cmd, SetInputMode):
            if cmd.port > 3 or cmd.sensor_type > SensorType.LOWSPEED_9V:
                return OUT_OF_RANGE, StatusReply(opcode=cmd.OPCODE)
            s = self.sensors[cmd.port]
            s.sensor_type, s.sensor_mode, s.mode_set_at = cmd.sensor_type, cmd.sensor_mode, t
            s.rx, s.busy_until, s.bus_error = None, -1e9, False
            return OK, StatusReply(opcode=cmd.OPCODE)
        if isinstance(cmd, GetInputValues):
            if cmd.port > 3:
                return OUT_OF_RANGE, InputValues(port=cmd.port)
            return OK, self._input_values(cmd.port)
        if isinstance(cmd, GetBatteryLevel):
            return OK, BatteryLevel(millivolts=self.cfg.battery_mv)
        if isinstance(cmd, KeepAlive):
            self._last_keepalive = time.monotonic()
            return OK, KeepAliveReply(sleep_limit_ms=round(self.cfg.sleep_limit_s * 1000))
        if isinstance(cmd, LsWrite | LsGetStatus | LsRead):
            return self._lowspeed(cmd, t)
        return 0xBE, StatusReply(opcode=cmd.OPCODE)

    def _input_values(self, port: int) -> InputValues:
        s = self.sensors[port]
        raw = 1023
        if s.sensor_type == SensorType.SWITCH:
            front, rear = self.world.bumpers()
            pressed = front if port == self.front_port else rear if port == self.rear_port else 0
            raw = 183 if pressed else 1023
        scaled = raw
        if s.sensor_mode == SensorMode.BOOLEAN:
            scaled = 1 if raw < 460 else 0
        return InputValues(
            port=port,
            valid=s.sensor_type != SensorType.NO_SENSOR,
            calibrated=False,
            sensor_type=s.sensor_type,
            sensor_mode=s.sensor_mode,
            raw=raw,
            normalized=raw,
            scaled=scaled,
            calibrated_value=scaled,
        )

    def _lowspeed(self, cmd: Command, t: float) -> tuple[int, Reply]:
        port = cmd.port  # type: ignore[attr-defined]
        reply_cls = {LsWrite: None, LsGetStatus: LsStatus, LsRead: LsReadReply}[type(cmd)]

        def status_only(code: int) -> tuple[int, Reply]:
            if reply_cls is None:
                return code, StatusReply(opcode=cmd.OPCODE)
            return code, reply_cls()

        if port > 3:
            return status_only(CHANNEL_INVALID)
        s = self.sensors[port]
        lowspeed = s.sensor_type in (SensorType.LOWSPEED, SensorType.LOWSPEED_9V)
        if not lowspeed or t - s.mode_set_at < self.cfg.i2c_pending_s:
            return status_only(CHANNEL_BUSY)
        if isinstance(cmd, LsWrite):
            if t < s.busy_until:
                return status_only(CHANNEL_BUSY)
            dev = self.devices.get(port)
            s.rx, s.bus_error = None, False
            s.busy_until = t + self.cfg.i2c_latency_s
            ok = (
                dev is not None
                and len(cmd.tx) >= 2
                and cmd.tx[0] == I2C_ADDRESS
                and (not dev.needs_9v or s.sensor_type == SensorType.LOWSPEED_9V)
            )
            if not ok:
                s.bus_error = True
                return OK, StatusReply(opcode=cmd.OPCODE)  # the NACK shows up later
            reg = cmd.tx[1]
            if len(cmd.tx) > 2:
                dev.write(reg, cmd.tx[2:])
            s.rx = dev.read(reg, cmd.rx_len) if cmd.rx_len else b""
            return OK, StatusReply(opcode=cmd.OPCODE)
        if t < s.busy_until:
            return status_only(PENDING)
        if s.bus_error:
            return status_only(BUS_ERROR)
        if isinstance(cmd, LsGetStatus):
            return OK, LsStatus(bytes_ready=len(s.rx or b""))
        data, s.rx = s.rx or b"", None
        return OK, LsReadReply(data=data)


assert STATUS_ERRORS[CHANNEL_BUSY].status == CHANNEL_BUSY


def serve(
    world: World,
    nxt: NxtConfig,
    cfg: EmulatorConfig,
    *,
    stop: threading.Event | None = None,
    print_fn: Callable[[str], None] = print,
) -> None:
    """Run the emulator until ``stop`` is set or Ctrl-C / SIGTERM; print the port path.

    This is the body of ``scenebot nxt-emulator``: point ``nxt.port`` at the printed
    path and run the campaign with ``robot: nxt`` (the real-hardware backend).
    """
    from scenebot.robot.nxt.robot import install_sigterm_handler

    install_sigterm_handler()
    stop = stop or threading.Event()
    with NxtEmulator(world, cfg, nxt) as emu:
        print_fn(f"NXT emulator listening on {emu.port_path} (pty {emu.pty_path})")
        print_fn(f"photos go to {emu.inbox}; Ctrl-C to stop")
        try:
            while not stop.wait(0.2):
                if emu.error is not None:
                    raise RuntimeError(f"NXT emulator crashed: {emu.error}") from emu.error
        except KeyboardInterrupt:
            pass
