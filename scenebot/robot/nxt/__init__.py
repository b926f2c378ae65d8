"""The LEGO NXT backend: direct-command driver over a Bluetooth serial port, camera trigger with
a photo inbox, and a byte-exact brick emulator on a pseudo-terminal.

Entry points for the lead:

* :func:`make_nxt_robot` -> ``(NxtRobot, NxtCamera)`` for ``robot: nxt`` (real port) and
  ``robot: nxt-emulated`` (pass the simulator ``world``: an emulator is started on a pty and
  the driver talks to it through pyserial).
* :func:`scenebot.robot.nxt.emulator.serve` for ``scenebot nxt-emulator``.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING

from scenebot.robot.nxt.config import EmulatorConfig, FaultConfig, NxtCameraConfig, NxtConfig

if TYPE_CHECKING:
    from scenebot.robot.nxt.camera import NxtCamera
    from scenebot.robot.nxt.client import Clock, NxtClient
    from scenebot.robot.nxt.robot import NxtRobot

_LAZY = {
    "NxtCamera": "scenebot.robot.nxt.camera",
    "NxtClient": "scenebot.robot.nxt.client",
    "Clock": "scenebot.robot.nxt.client",
    "open_serial": "scenebot.robot.nxt.client",
    "NxtRobot": "scenebot.robot.nxt.robot",
    "install_sigterm_handler": "scenebot.robot.nxt.robot",
}


def __getattr__(name: str):
    """Import the driver modules only when used: the workflow loads the config at start."""
    import importlib

    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "EmulatorConfig",
    "FaultConfig",
    "NxtCamera",
    "NxtCameraConfig",
    "NxtClient",
    "NxtConfig",
    "NxtRobot",
    "connect",
    "make_nxt_robot",
]


def connect(cfg: NxtConfig, clock: Clock | None = None) -> NxtClient:
    """Open ``cfg.port`` and greet the brick (KEEPALIVE).

    Raises:
        PortNotFoundError, PortBusyError, BrickNotAnsweringError: with what to check.
    """
    from scenebot.robot.nxt.client import NxtClient, open_serial

    def opener():
        return open_serial(cfg.port, cfg.baudrate)

    client = NxtClient.from_config(opener(), cfg, clock=clock, opener=opener)
    try:
        client.handshake()
    except BaseException:
        client.close()
        raise
    return client


def make_nxt_robot(
    cfg: NxtConfig,
    *,
    world=None,
    emulator: EmulatorConfig | None = None,
    clock: Clock | None = None,
    watchdog: bool = True,
    sigterm: bool = True,
) -> tuple[NxtRobot, NxtCamera]:
    """Build the NXT robot and camera.

    Args:
        cfg: NXT settings (``port`` is used unless ``world`` is given).
        world: a simulator world: start a brick emulator on a pty backed by it
            (``robot: nxt-emulated``); the robot geometry is taken from ``world.params`` and
            the inbox folder is created. The emulator stops when the robot is closed.
        emulator: emulator settings (faults, timing); its ``inbox`` is replaced by
            ``cfg.camera.inbox``.
        clock: time source (tests).
        watchdog: run the watchdog thread.
        sigterm: turn SIGTERM into an exception so ``with``/``finally`` blocks stop the motors
            (main thread only).

    Returns:
        ``(robot, camera)``; use ``with robot:`` (or call ``robot.close()``) on every path.
    """
    from scenebot.robot.nxt.camera import NxtCamera
    from scenebot.robot.nxt.emulator import NxtEmulator
    from scenebot.robot.nxt.robot import NxtRobot, install_sigterm_handler

    emu = None
    if world is not None:
        p = world.params
        cfg = cfg.model_copy(
            update={
                "wheel_radius_m": float(p.wheel_radius_m),
                "wheel_base_m": float(p.wheel_base_m),
                "max_wheel_speed_deg_s": float(p.max_wheel_speed_deg_s),
            }
        )
        cfg.camera.inbox.mkdir(parents=True, exist_ok=True)
        emu_cfg = (emulator or EmulatorConfig()).model_copy(update={"inbox": cfg.camera.inbox})
        emu = NxtEmulator(world, emu_cfg, cfg).start()
        cfg = cfg.model_copy(update={"port": emu.port_path})
    try:
        client = connect(cfg, clock)
        try:
            robot = NxtRobot(client, cfg, clock, watchdog=watchdog)
            camera = NxtCamera(client, cfg.camera, clock)
            camera.before_trigger = functools.partial(robot.check_brick, "photo")
        except BaseException:
            client.close()
            raise
    except BaseException:
        if emu is not None:
            emu.close()
        raise
    if emu is not None:
        robot.owned.append(emu)
        robot.emulator = emu
    if sigterm:
        install_sigterm_handler()
    return robot, camera
