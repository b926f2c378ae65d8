"""NxtRobot: the :class:`scenebot.robot.base.Robot` interface on a LEGO NXT brick.

Motions start both wheel motors with a tacho limit and then poll the brick (motor state,
bumpers) until the firmware reports the limit reached, a bumper closes, a wheel stalls (its
rotation count stops advancing although powered), or the motion times out. Every command that
powers a wheel carries a tacho limit (:func:`run_command` refuses none), so a host that dies
mid-motion (SIGKILL) leaves the wheels running at most to that limit: that is the worst case.
Every poll, and every request or reply on the link, is a heartbeat for the host-side watchdog
thread, which stops the motors if the control loop goes silent while they run (motors keep
running on the brick when the host stops talking); a control loop waiting on a slow link is
not silent.

Safety: the motors and the camera port are switched off by :meth:`NxtRobot.close`, which runs
from ``with`` blocks, ``atexit`` and (through :func:`install_sigterm_handler`) SIGTERM; after
a reconnect the motors are stopped first (they keep running through a link drop).

A brick reboot (sensor modes lost, tacho counters reset) is detected from the bumper port type,
which is always read *after* the wheel counters it vouches for: at the start and end of every
motion, before every photo trigger (:meth:`NxtRobot.check_brick`), on every poll and in every
sensor reading. The sensors are then set up again and odometry is rebaselined on the reset
counters, so it continues from the last good pose; reset counters never enter odometry. Each
recovered fault (reboot, lost reply, link drop, watchdog stop, resent start) is reported as a
``fault`` event that :meth:`NxtRobot.drain_faults` hands to the capture log.
"""

from __future__ import annotations

import atexit
import logging
import math
import signal
import threading
import weakref
from dataclasses import dataclass, replace

from scenebot.robot.base import (
    Health,
    LinkLostError,
    MotionResult,
    MotionStatus,
    Pose2D,
    Robot,
    RobotError,
    SensorReading,
)
from scenebot.robot.nxt.client import Clock, NxtClient, SystemClock
from scenebot.robot.nxt.config import NxtConfig, motor_index, sensor_index
from scenebot.robot.nxt.protocol import (
    ALL_MOTORS,
    BusError,
    ChannelBusyError,
    DirectCommandError,
    OutputMode,
    OutputState,
    ProtocolError,
    RegulationMode,
    RunState,
    SetOutputState,
)
from scenebot.robot.nxt.sensors import (
    HiTechnicCompass,
    Odometry,
    SensorModeLost,
    SensorReadError,
    StallDetector,
    TouchSensor,
    Ultrasonic,
)

log = logging.getLogger(__name__)

LIMIT_TOLERANCE_DEG = 12
"""A motion whose wheels stopped within this many degrees of the tacho limit completed."""

PAIR_SKEW_MAX_S = 0.05
"""Mid-motion, the two wheel counters (read one after the other) enter odometry only if both
reads took at most this long (s). A pair read across a lost reply is skewed in time: during a
turn in place it looks like a translation. The counters after the stop are always used, so
the skipped increment enters odometry there, as one segment (exact for a turn or a straight)."""


def brake_command(port: int) -> SetOutputState:
    """Active brake: power 0, regulated, running (holds the wheel); safe to repeat."""
    return SetOutputState(
        port=port,
        power=0,
        mode=OutputMode.MOTORON | OutputMode.BRAKE | OutputMode.REGULATED,
        regulation=RegulationMode.MOTOR_SPEED,
        turn_ratio=0,
        run_state=RunState.RUNNING,
        tacho_limit=0,
    )


def off_command(port: int) -> SetOutputState:
    """Output off (coast, idle); safe to repeat. ``port`` may be ``ALL_MOTORS``."""
    return SetOutputState(
        port=port,
        power=0,
        mode=OutputMode.COAST,
        regulation=RegulationMode.IDLE,
        turn_ratio=0,
        run_state=RunState.IDLE,
        tacho_limit=0,
    )


def run_command(port: int, power: int, limit_deg: int) -> SetOutputState:
    """Speed-regulated run for ``limit_deg`` degrees (then the firmware brakes).

    Raises:
        ValueError: ``limit_deg`` is not positive (a wheel never runs without a tacho limit).
    """
    if limit_deg <= 0:
        raise ValueError(
            f"motor port {port}: a wheel motion needs a tacho limit > 0 deg, got {limit_deg} "
            "(without one the wheel would run on if the host died)"
        )
    return SetOutputState(
        port=port,
        power=power,
        mode=OutputMode.MOTORON | OutputMode.BRAKE | OutputMode.REGULATED,
        regulation=RegulationMode.MOTOR_SPEED,
        turn_ratio=0,
        run_state=RunState.RUNNING,
        tacho_limit=limit_deg,
    )


@dataclass
class _Wheel:
    port: int
    sign: int  # +1 if positive power drives this wheel forward


class NxtRobot(Robot):
    """A differential-drive NXT robot (two wheel motors, two bumpers, compass, ultrasonic).

    Args:
        client: a connected :class:`NxtClient` (handshake done).
        cfg: the NXT settings.
        clock: time source (shared with the client; default the real clock).
        watchdog: start the watchdog thread (tests with a fake clock call
            :meth:`watchdog_check` instead).
    """

    def __init__(
        self,
        client: NxtClient,
        cfg: NxtConfig,
        clock: Clock | None = None,
        watchdog: bool = True,
    ):
        self.client, self.cfg = client, cfg
        self.clock = clock or client.clock or SystemClock()
        sign = -1 if cfg.reverse_motors else 1
        self.left = _Wheel(motor_index(cfg.left_motor), sign)
        self.right = _Wheel(motor_index(cfg.right_motor), sign)
        self.camera_port = motor_index(cfg.camera.port)
        self.front = TouchSensor(client, sensor_index(cfg.bumper_front), "front bumper")
        self.rear = TouchSensor(client, sensor_index(cfg.bumper_rear), "rear bumper")
        self.compass = HiTechnicCompass(
            client,
            sensor_index(cfg.compass),
            self.clock,
            cfg.compass_convention,
            cfg.compass_offset_deg,
        )
        self.ultrasonic = Ultrasonic(client, sensor_index(cfg.ultrasonic), self.clock)
        self.reboots = 0
        self.link_drops = 0
        self.watchdog_trips = 0
        self._moving = False
        self._watchdog_tripped = False
        self._last_heartbeat = self.clock.monotonic()
        self._last_battery_check = -math.inf
        self._closed = False
        self.owned: list = []  # closed after the client (e.g. the emulator)
        self.emulator = None

        self.client.on_reconnect.append(self._after_reconnect)
        self.client.on_activity.append(self._link_activity)
        self._wd_thread: threading.Thread | None = None
        self.all_off()  # whatever a previous run left on
        self.check_battery(force=True)
        self.setup_sensors()
        try:
            heading = self.compass.heading_ccw_deg()
        except (BusError, ChannelBusyError, SensorReadError) as exc:
            raise RobotError(
                f"the compass on sensor port {self.compass.port + 1} does not answer ({exc}): "
                "check that a HiTechnic compass is plugged in there (nxt.compass)"
            ) from exc
        self.odometry = Odometry(cfg.wheel_radius_m, cfg.wheel_base_m, Pose2D(0.0, 0.0, 0.0))
        self.odometry.pose = Pose2D(0.0, 0.0, math.radians(heading))
        self.odometry.rebaseline(*self._wheel_counts())

        self._wd_stop = threading.Event()
        if watchdog:
            self._wd_thread = threading.Thread(
                target=self._watchdog_loop, name="nxt-watchdog", daemon=True
            )
            self._wd_thread.start()
        self._atexit = _weak_close(self)
        atexit.register(self._atexit)

    # ------------------------------------------------------------------ setup & health

    def setup_sensors(self) -> None:
        """Set the sensor port modes and program the I2C sensors.

        Raises:
            RobotError: a sensor does not answer (names the port and the config key).
        """
        keys = {
            self.front: "bumper_front",
            self.rear: "bumper_rear",
            self.compass: "compass",
            self.ultrasonic: "ultrasonic",
        }
        for sensor, key in keys.items():
            try:
                sensor.setup()
            except (BusError, ChannelBusyError, SensorReadError) as exc:
                raise RobotError(
                    f"the {sensor.name} on sensor port {sensor.port + 1} does not answer "
                    f"({exc}): check its cable and nxt.{key}"
                ) from exc

    def check_battery(self, force: bool = False) -> int | None:
        """Check the battery if the configured interval has passed (or ``force``)."""
        now = self.clock.monotonic()
        if not force and now - self._last_battery_check < self.cfg.battery_check_interval_s:
            return None
        self._last_battery_check = now
        return self.client.check_battery(self.cfg.battery_min_mv)

    def health(self) -> Health:
        link_ok = True
        try:
            mv = self.client.battery_mv()
        except (ProtocolError, RobotError, OSError):
            mv, link_ok = None, False
        return Health(
            battery_mv=mv,
            link_ok=link_ok,
            details={
                "reboots": self.reboots,
                "link_drops": self.link_drops,
                "watchdog_trips": self.watchdog_trips,
                "retries": self.client.stats.retries,
                "timeouts": self.client.stats.timeouts,
                "reconnects": self.client.stats.reconnects,
            },
        )

    @property
    def now(self) -> float:
        return self.clock.monotonic()

    @property
    def pose(self) -> Pose2D:
        """Current odometry pose."""
        return self.odometry.pose

    # ------------------------------------------------------------------ sensing

    def _wheel_counts(self) -> tuple[float, float]:
        """Cumulative forward wheel rotations (deg) from the rotation counters."""
        sl = self.client.output_state(self.left.port)
        sr = self.client.output_state(self.right.port)
        return self.left.sign * sl.rotation_count, self.right.sign * sr.rotation_count

    def _recover_reboot(self, cause: Exception, during: str) -> tuple[float, float]:
        """The brick rebooted: set the sensors up again and rebaseline odometry on the reset
        counters (it continues from the last good pose); return those counters.

        Args:
            cause: how the reboot showed.
            during: the step that found it (``turn``, ``drive``, ``photo``, ``sense``).
        """
        self.reboots += 1
        log.warning("NXT brick rebooted (%s, found at a %s): setting sensor modes again",
                    cause, during)  # fmt: skip
        self.stop()
        self.setup_sensors()
        counts = self._wheel_counts()
        self.odometry.rebaseline(*counts)
        self.client.record_fault(
            "brick_reboot",
            recovered=True,
            during=during,
            action="sensor modes set again; odometry rebaselined on the reset wheel counters",
            odometry=self.odometry.pose.as_dict(),
            detail=str(cause),
        )
        return counts

    def _sync(self, during: str) -> tuple[float, float]:
        """Bring odometry up to date, checking for a brick reboot before the counters are used.

        The bumper's port type is read after the wheel counters: if the brick rebooted before
        the counter read, the type shows it, and the (reset) counters are taken as the new
        baseline instead of as motion. Returns the counters odometry now stands on.
        """
        counts = self._wheel_counts()
        try:
            self.front.pressed()
        except SensorModeLost as exc:
            return self._recover_reboot(exc, during)
        self.odometry.update(*counts)
        return counts

    def check_brick(self, during: str = "photo") -> None:
        """Check for a brick reboot (and recover from it) before a step that is not a motion,
        e.g. a photo trigger; odometry is brought up to date on the way."""
        with self.client.lock:
            self._sync(during)

    def drain_faults(self) -> list[dict]:
        """The recovered faults since the last call, as ``{"type": "fault", ...}`` records
        (``t`` on the robot clock, ``fault``: ``brick_reboot``, ``reply_lost``,
        ``reply_garbled``, ``link_lost``, ``watchdog_stop`` or ``motor_start_resent``)."""
        return self.client.drain_faults()

    def sense(self) -> SensorReading:
        for attempt in range(2):
            try:
                counts = self._wheel_counts()
                front = self.front.pressed()
                rear = self.rear.pressed()  # type checks after the tacho read: see module doc
                self.odometry.update(*counts)
                return SensorReading(
                    t=self.now,
                    compass_deg=self.compass.heading_ccw_deg(),
                    ultrasonic_cm=self.ultrasonic.distance_cm(),
                    bump_front=front,
                    bump_rear=rear,
                    odometry=self.odometry.pose,
                )
            except SensorModeLost as exc:
                if attempt:
                    raise RobotError(
                        f"NXT sensors lose their modes repeatedly ({exc}): check the brick's "
                        "batteries and the sensor cables"
                    ) from exc
                self._recover_reboot(exc, "sense")
            except ProtocolError as exc:  # retries and redone transactions did not help
                raise RobotError(
                    f"reading the NXT sensors failed ({exc}): check the Bluetooth link, the "
                    "brick's batteries and the sensor cables"
                ) from exc
        raise AssertionError("unreachable")

    # ------------------------------------------------------------------ motion

    def stop(self) -> None:
        """Brake both wheels (best effort: never raises)."""
        for w in (self.left, self.right):
            try:
                self.client.request(brake_command(w.port))
            except (ProtocolError, RobotError, OSError) as exc:
                log.error("could not stop motor port %d: %s", w.port, exc)

    def all_off(self) -> bool:
        """Switch every motor port off (wheels and camera); True if the brick confirmed.

        Never raises: a dead link is logged (the tacho limits stop the wheels by themselves).
        """
        try:
            self.client.request(off_command(ALL_MOTORS))
            return True
        except DirectCommandError:  # a firmware refusing port 0xFF: one port at a time
            ok = True
            for port in range(3):
                try:
                    self.client.request(off_command(port))
                except (ProtocolError, RobotError, OSError) as exc:
                    log.error("could not switch motor port %d off: %s", port, exc)
                    ok = False
            return ok
        except (ProtocolError, RobotError, OSError) as exc:
            log.error("could not switch the NXT outputs off: %s", exc)
            return False

    def drive(self, distance_m: float) -> MotionResult:
        deg = abs(distance_m) / self.cfg.wheel_radius_m * 180.0 / math.pi
        s = 1 if distance_m >= 0 else -1
        bumper = ("front",) if s > 0 else ("rear",)
        return self._motion(
            s * self.cfg.drive_power, s * self.cfg.drive_power, deg, bumper, "drive"
        )

    def turn(self, angle_rad: float) -> MotionResult:
        arc = abs(angle_rad) * 0.5 * self.cfg.wheel_base_m
        deg = arc / self.cfg.wheel_radius_m * 180.0 / math.pi
        s = 1 if angle_rad >= 0 else -1  # counter-clockwise: right wheel forward
        p = self.cfg.turn_power
        # A round robot turning in place pushes into nothing: bumpers do not stop turns
        # (as in the simulator backend); a blocked wheel still shows as a stall.
        return self._motion(-s * p, s * p, deg, (), "turn")

    def _started(self, wheel: _Wheel, cmd: SetOutputState) -> bool:
        st = self.client.output_state(wheel.port)
        if st.tacho_limit != cmd.tacho_limit:
            return False  # every motion ends with a brake command that sets the limit to 0
        if st.running and st.power == cmd.power:
            return True
        # already idle: started only if it covered (most of) its limit since the command
        done = max(1, cmd.tacho_limit - LIMIT_TOLERANCE_DEG)
        return cmd.tacho_limit > 0 and abs(st.tacho_count) >= done

    def _start_pair(self, power_l: int, power_r: int, limit: int) -> None:
        """Start both wheels back to back (no-reply telegrams, so no round trip and no lost
        reply can separate them), then read both states back and resend to a wheel that did
        not start."""
        cmds = [
            (w, run_command(w.port, w.sign * pw, limit))
            for w, pw in ((self.left, power_l), (self.right, power_r))
        ]
        for _, cmd in cmds:
            self.client.request(replace(cmd, reply=False))
        for w, cmd in cmds:
            if not self._started(w, cmd):
                log.warning("motor port %d did not start; sending the command again", w.port)
                self.client.request(cmd)
                self.client.record_fault(
                    "motor_start_resent",
                    recovered=True,
                    port=w.port,
                    action="the start command was lost: sent again (with a reply)",
                )

    def _motion(
        self,
        power_l: int,
        power_r: int,
        limit_deg: float,
        bumpers: tuple[str, ...],
        what: str,
    ) -> MotionResult:
        """Run both wheels to a tacho limit and watch bumpers, stalls and the brick.

        Args:
            power_l, power_r: signed motor power (%, forward positive).
            limit_deg: wheel rotation to do (deg, both wheels).
            bumpers: bumpers that stop this motion.
            what: ``drive`` or ``turn`` (for the fault log).
        """
        limit = round(limit_deg)
        t0 = self.now
        if limit == 0:
            return MotionResult(MotionStatus.COMPLETED, duration_s=0.0)
        speed = self.cfg.max_wheel_speed_deg_s * max(abs(power_l), abs(power_r)) / 100.0
        timeout = self.cfg.motion_timeout_factor * limit / speed + 1.0
        pose0 = self.odometry.pose
        try:
            self.check_battery()
            counts0 = self._sync(what)  # a reboot since the last step: counters reset, modes lost
        except ProtocolError as exc:
            raise RobotError(
                f"the NXT does not answer before a {what} ({exc}): check the Bluetooth link and "
                "the brick's batteries"
            ) from exc
        drops0 = self.link_drops
        stall = {
            w.port: StallDetector(self.cfg.stall_window_s, self.cfg.stall_min_deg)
            for w in (self.left, self.right)
        }
        status, which = MotionStatus.COMPLETED, None
        self._watchdog_tripped = False
        self._heartbeat()
        self._moving = True
        try:
            self._start_pair(power_l, power_r, limit)
            while True:
                self._heartbeat()
                if self._watchdog_tripped:
                    status = MotionStatus.STALLED
                    break
                t_read = self.now
                sl = self.client.output_state(self.left.port)
                sr = self.client.output_state(self.right.port)
                skew = self.now - t_read
                try:
                    pressed = {"front": self.front.pressed(), "rear": self.rear.pressed()}
                except SensorModeLost as exc:
                    self._recover_reboot(exc, what)
                    status = MotionStatus.LINK_LOST
                    break
                counts = (self.left.sign * sl.rotation_count, self.right.sign * sr.rotation_count)
                if skew <= PAIR_SKEW_MAX_S:
                    self.odometry.update(*counts)
                if self.link_drops != drops0:
                    status = MotionStatus.LINK_LOST
                    break
                hit = [b for b in bumpers if pressed[b]]
                if hit:
                    status, which = MotionStatus.BUMPED, hit[0]
                    break
                t = self.now
                if any(
                    st.running and stall[st.port].update(t, st.rotation_count) for st in (sl, sr)
                ):
                    status = MotionStatus.STALLED
                    break
                if not sl.running and not sr.running:
                    status = self._finished_status(sl, sr, counts0, counts, limit)
                    break
                if t - t0 > timeout:
                    log.warning("motion timed out after %.1f s", t - t0)
                    status = MotionStatus.STALLED
                    break
                self.clock.sleep(self.cfg.poll_s)
        except ProtocolError as exc:
            if self.link_drops == drops0:
                raise LinkLostError(
                    f"the NXT stopped answering during a motion ({exc}): check the Bluetooth "
                    "link and the brick's batteries"
                ) from exc
            status = MotionStatus.LINK_LOST
        finally:
            self._moving = False
            self.stop()
        try:
            self._sync(what)
        except ProtocolError as exc:
            raise RobotError(
                f"the NXT stopped answering after a {what} ({exc}): check the Bluetooth link "
                "and the brick's batteries"
            ) from exc
        return self._result(status, which, pose0, t0)

    def _finished_status(
        self,
        sl: OutputState,
        sr: OutputState,
        counts0: tuple[float, float],
        counts: tuple[float, float],
        limit: int,
    ) -> MotionStatus:
        done = [
            abs(c - c0) >= limit - LIMIT_TOLERANCE_DEG
            for c, c0 in zip(counts, counts0, strict=False)
        ]
        if all(done):
            return MotionStatus.COMPLETED
        # Motors stopped short of the limit without our stop: the watchdog, another program
        # on the brick, or a reboot the next poll would show. Treat as stalled.
        log.warning("motors stopped short of the tacho limit (%s, %s)", sl, sr)
        return MotionStatus.STALLED

    def _result(
        self, status: MotionStatus, bumper: str | None, pose0: Pose2D, t0: float
    ) -> MotionResult:
        p = self.odometry.pose
        heading = math.atan2(math.sin(pose0.theta), math.cos(pose0.theta))
        dx, dy = p.x - pose0.x, p.y - pose0.y
        dist = dx * math.cos(heading) + dy * math.sin(heading)
        dth = math.atan2(math.sin(p.theta - pose0.theta), math.cos(p.theta - pose0.theta))
        return MotionResult(status, dist, dth, bumper, self.now - t0)

    # ------------------------------------------------------------------ safety

    def _heartbeat(self) -> None:
        self._last_heartbeat = self.clock.monotonic()

    def _link_activity(self) -> None:
        """Client hook: the control loop is talking to the brick (or waiting on it)."""
        if threading.current_thread() is not self._wd_thread:
            self._heartbeat()

    def watchdog_check(self) -> bool:
        """One watchdog step: stop the motors if a motion's control loop has been silent
        longer than ``watchdog_timeout_s``; otherwise keep the brick awake. True if it fired."""
        if self._closed:
            return False
        silent = self.clock.monotonic() - self._last_heartbeat
        if self._moving and silent > self.cfg.watchdog_timeout_s and not self._watchdog_tripped:
            if not self.client.lock.acquire(timeout=self.cfg.watchdog_timeout_s):
                log.warning(
                    "watchdog: the control loop has waited on the link for %.1f s (the tacho "
                    "limit bounds the motion)",
                    silent,
                )
                return False
            try:
                # the control loop may have been waiting on a slow link (holding the lock):
                # only a loop still silent now that the link is free has hung
                silent = self.clock.monotonic() - self._last_heartbeat
                if not self._moving or silent <= self.cfg.watchdog_timeout_s:
                    return False
                log.error("watchdog: control loop silent for %.1f s, stopping the motors", silent)
                self._watchdog_tripped = True
                self.watchdog_trips += 1
                self.stop()
                self.client.record_fault(
                    "watchdog_stop",
                    recovered=True,
                    silent_s=silent,
                    action="motors stopped; the motion ends as stalled",
                )
            finally:
                self.client.lock.release()
            return True
        if not self._moving and self.client.lock.acquire(blocking=False):
            try:
                self.client.maybe_keepalive()
            except (ProtocolError, RobotError, OSError) as exc:
                log.warning("watchdog keepalive failed: %s", exc)
            finally:
                self.client.lock.release()
        return False

    def _watchdog_loop(self) -> None:
        period = min(0.25, self.cfg.watchdog_timeout_s / 4.0)
        while not self._wd_stop.wait(period):
            try:
                self.watchdog_check()
            except Exception as exc:  # the watchdog must never die silently
                log.exception("watchdog error: %s", exc)

    def _after_reconnect(self) -> None:
        """Runs inside the client after it reopened the port: motors ran on, stop them."""
        self.link_drops += 1
        self.client.keepalive()
        for w in (self.left, self.right):
            self.client.request(brake_command(w.port))
        self.client.request(off_command(self.camera_port))

    def close(self) -> None:
        """Stop the watchdog, switch all outputs off, release the port. Idempotent."""
        if self._closed:
            return
        self._closed = True
        self._wd_stop.set()
        if self._wd_thread is not None and self._wd_thread is not threading.current_thread():
            self._wd_thread.join(timeout=2.0)
        self._moving = False
        self.all_off()
        self.client.close()
        atexit.unregister(self._atexit)
        for obj in self.owned:
            obj.close()


def _weak_close(robot: NxtRobot):
    ref = weakref.ref(robot)

    def close() -> None:
        r = ref()
        if r is not None:
            r.close()

    return close


class Terminated(SystemExit):
    """Raised in the main thread when SIGTERM arrives (so ``finally``/``with`` blocks run)."""


def install_sigterm_handler() -> bool:
    """Turn SIGTERM (Snakemake killing a job, ``kill``) into :class:`Terminated` so the
    robot's ``close`` runs. Only possible from the main thread; returns whether installed."""
    if threading.current_thread() is not threading.main_thread():
        return False

    def handler(signum, frame):
        raise Terminated(128 + signum)

    signal.signal(signal.SIGTERM, handler)
    return True
