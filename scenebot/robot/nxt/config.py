"""Configuration of the LEGO NXT backend and of its brick emulator (merged by the lead)."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field, field_validator, model_validator

from scenebot.settings import Settings

MOTOR_PORTS = {"A": 0, "B": 1, "C": 2}


class NxtCameraConfig(Settings):
    """The CHDK camera triggered through a motor port; photos arrive in an inbox folder."""

    port: Literal["A", "B", "C"] = Field(
        "A", description="Motor port wired (through a 5 V regulator) to the camera's USB power."
    )
    pulse_s: float = Field(
        0.3,
        gt=0.0,
        description="Trigger pulse length (s). CHDK samples USB power every ~10 ms and misses "
        "short pulses.",
    )
    power: int = Field(100, ge=1, le=100, description="Motor port power during the pulse (%).")
    inbox: Path = Field(
        Path("inbox"),
        description="Folder the Wi-Fi SD card uploads photos into (must exist).",
    )
    timeout_s: float = Field(
        30.0, gt=0.0, description="Seconds after the trigger before capture gives up."
    )
    poll_s: float = Field(0.05, gt=0.0, description="Inbox polling period (s).")
    stable_polls: int = Field(
        2, ge=1, description="Polls a file's size must stay unchanged before it is read."
    )


class NxtConfig(Settings):
    """The NXT robot: serial link, port wiring, geometry, motion and safety settings."""

    port: str = Field(
        "/dev/rfcomm0", description="Serial port of the brick (rfcomm device or emulator pty)."
    )
    baudrate: int = Field(115200, gt=0, description="Serial baud rate (ignored by rfcomm/pty).")
    reply_timeout_s: float = Field(
        0.5, gt=0.0, description="Time (s) to wait for a complete reply telegram."
    )
    retries: int = Field(
        2, ge=0, description="Extra attempts for commands that are safe to repeat."
    )
    reconnect_attempts: int = Field(
        5, ge=0, description="Times to reopen the port after the link drops."
    )
    reconnect_delay_s: float = Field(0.5, ge=0.0, description="Pause between reopen attempts (s).")
    keepalive_interval_s: float = Field(
        60.0,
        gt=0.0,
        description="Send KEEPALIVE at least this often (s); also never later than half the "
        "brick's sleep timer. Motor commands do not reset the sleep timer.",
    )
    battery_min_mv: int = Field(
        6300, ge=0, description="Refuse to move below this battery voltage (mV)."
    )
    battery_check_interval_s: float = Field(
        30.0, ge=0.0, description="Re-check the battery between moves at most this often (s)."
    )
    left_motor: Literal["A", "B", "C"] = Field("B", description="Left wheel motor port.")
    right_motor: Literal["A", "B", "C"] = Field("C", description="Right wheel motor port.")
    reverse_motors: bool = Field(
        False, description="True if positive motor power drives the robot backwards."
    )
    bumper_front: int = Field(1, ge=1, le=4, description="Sensor port of the front bumper.")
    bumper_rear: int = Field(2, ge=1, le=4, description="Sensor port of the rear bumper.")
    compass: int = Field(3, ge=1, le=4, description="Sensor port of the HiTechnic compass.")
    ultrasonic: int = Field(4, ge=1, le=4, description="Sensor port of the LEGO ultrasonic.")
    compass_convention: Literal["clockwise", "counter_clockwise"] = Field(
        "clockwise",
        description="How the compass counts: 'clockwise' (HiTechnic sensor, real compass); "
        "the driver converts to counter-clockwise (360 - h, as the RWTH MATLAB toolbox).",
    )
    compass_offset_deg: float = Field(
        0.0, description="Added to the counter-clockwise heading (deg), for mounting offsets."
    )
    wheel_radius_m: float = Field(0.028, gt=0.0, description="Wheel radius (m).")
    wheel_base_m: float = Field(0.12, gt=0.0, description="Distance between wheel contacts (m).")
    max_wheel_speed_deg_s: float = Field(
        900.0, gt=0.0, description="Wheel speed at power 100 (deg/s); sets motion timeouts."
    )
    drive_power: int = Field(50, ge=1, le=100, description="Motor power when driving (%).")
    turn_power: int = Field(33, ge=1, le=100, description="Motor power when turning (%).")
    poll_s: float = Field(0.02, ge=0.0, description="Pause between motion status polls (s).")
    stall_window_s: float = Field(
        0.6,
        gt=0.0,
        description="A powered wheel that turns less than stall_min_deg within "
        "this window (s) is stalled.",
    )
    stall_min_deg: float = Field(4.0, gt=0.0, description="See stall_window_s (deg).")
    motion_timeout_factor: float = Field(
        4.0, gt=1.0, description="A motion may take this times its nominal duration."
    )
    watchdog_timeout_s: float = Field(
        2.0,
        gt=0.0,
        description="Stop the motors if the control loop is silent this long (s) while they run.",
    )
    camera: NxtCameraConfig = Field(default_factory=NxtCameraConfig)

    @model_validator(mode="after")
    def _distinct_ports(self) -> NxtConfig:
        motors = [self.left_motor, self.right_motor, self.camera.port]
        if len(set(motors)) != 3:
            raise ValueError(
                f"nxt: left_motor, right_motor and camera.port must be different motor "
                f"ports, got {motors}"
            )
        sensors = [self.bumper_front, self.bumper_rear, self.compass, self.ultrasonic]
        if len(set(sensors)) != 4:
            raise ValueError(
                f"nxt: bumper_front, bumper_rear, compass and ultrasonic must be "
                f"different sensor ports 1-4, got {sensors}"
            )
        return self


class FaultConfig(Settings):
    """Faults the brick emulator injects. Command indices count every received command
    telegram from 0 (so tests can place a fault exactly)."""

    drop_reply_at: list[int] = Field(
        default_factory=list, description="Execute these commands but send no reply."
    )
    drop_reply_prob: float = Field(
        0.0, ge=0.0, le=1.0, description="Probability of dropping any other reply."
    )
    drop_command_at: list[int] = Field(
        default_factory=list, description="Lose these commands in transit (never executed)."
    )
    late_reply_at: list[int] = Field(
        default_factory=list, description="Send the reply to these commands late."
    )
    late_reply_s: float = Field(1.5, ge=0.0, description="Delay of a late reply (s).")
    split_frames: bool = Field(
        False, description="Send every reply in small pieces with pauses (short reads)."
    )
    split_gap_s: float = Field(0.004, ge=0.0, description="Pause between the pieces (s).")
    reboot_at: list[int] = Field(
        default_factory=list,
        description="Reboot the brick just before these commands: motors stop, tachos and "
        "sensor modes reset.",
    )
    vanish_at: list[int] = Field(
        default_factory=list,
        description="Make the port vanish (link drops) just before these commands.",
    )
    vanish_for_s: float | None = Field(
        1.0, description="Seconds until the port reappears at the same path; null = never."
    )
    seed: int = Field(0, description="Random seed for drop_reply_prob.")


class EmulatorConfig(Settings):
    """The NXT brick emulator on a pseudo-terminal, backed by the simulator's physics."""

    link_path: Path | None = Field(
        None,
        description="Stable path (a symlink to the pty, like /dev/rfcomm0) the driver opens; "
        "default: a temporary file.",
    )
    time_scale: float = Field(1.0, gt=0.0, description="Simulated seconds per wall-clock second.")
    physics_dt_s: float = Field(0.01, gt=0.0, description="Physics step (simulated s).")
    battery_mv: int = Field(8100, ge=0, description="Reported battery voltage (mV).")
    sleep_limit_s: float = Field(
        600.0,
        ge=0.0,
        description="Brick switches off after this long without KEEPALIVE "
        "(s, wall clock; 0 = never).",
    )
    i2c_pending_s: float = Field(
        0.02,
        ge=0.0,
        description="Digital sensor commands answer 0xE0 this long after a mode change (s).",
    )
    i2c_latency_s: float = Field(
        0.005, ge=0.0, description="Time an I2C transaction takes before data is ready (s)."
    )
    camera_min_pulse_s: float = Field(
        0.1, ge=0.0, description="Shortest motor-port pulse the camera notices (s)."
    )
    shutter_delay_s: float = Field(
        0.1, ge=0.0, description="Time from trigger to the upload start (s)."
    )
    upload_chunk_bytes: int = Field(8192, ge=1, description="Upload chunk size (bytes).")
    upload_chunk_interval_s: float = Field(
        0.02, ge=0.0, description="Pause between upload chunks (s)."
    )
    inbox: Path = Field(Path("inbox"), description="Folder the emulated Wi-Fi card writes to.")
    faults: FaultConfig = Field(default_factory=FaultConfig)

    @field_validator("inbox")
    @classmethod
    def _inbox_path(cls, v: Path) -> Path:
        return Path(v)


def motor_index(port: str) -> int:
    """Motor port letter -> protocol port number (A=0, B=1, C=2)."""
    return MOTOR_PORTS[port]


def sensor_index(port: int) -> int:
    """Sensor port 1-4 (as printed on the brick) -> protocol port number 0-3."""
    return port - 1
