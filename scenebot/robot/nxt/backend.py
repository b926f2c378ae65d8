"""The NXT backends as the factory (:mod:`scenebot.robot.factory`) builds them, and the body
of ``scenebot nxt-emulator``. A simulated world, where one is needed, is handed in."""

from __future__ import annotations

from pathlib import Path

from scenebot.robot.nxt import make_nxt_robot
from scenebot.robot.nxt.camera import NxtCamera
from scenebot.robot.nxt.config import EmulatorConfig, NxtConfig
from scenebot.robot.nxt.robot import NxtRobot


def make_nxt_backend(
    nxt: NxtConfig,
    *,
    world=None,
    emulator: EmulatorConfig | None = None,
    inbox: Path | None = None,
) -> tuple[NxtRobot, NxtCamera]:
    """``(robot, camera)`` for ``robot: nxt`` (``world`` None) or ``nxt-emulated``.

    Args:
        nxt: the NXT settings.
        world: ``nxt-emulated``: the :class:`~scenebot.sim.world.SimWorld` that backs the
            brick emulator (started on a pty, the driver talks to it through pyserial);
            None: the real brick on ``nxt.port``.
        emulator: emulator settings (timing, faults).
        inbox: photo inbox to use instead of ``nxt.camera.inbox`` (e.g. a folder inside the
            capture directory for the emulator, so the final move is a same-disk rename).
    """
    if inbox is not None:
        nxt = nxt.model_copy(
            update={"camera": nxt.camera.model_copy(update={"inbox": Path(inbox)})}
        )
    if world is None:
        return make_nxt_robot(nxt)
    robot, camera = make_nxt_robot(nxt, world=world, emulator=emulator)
    # like the simulator backend, log the true pose for evaluation (never used to decide)
    robot.truth_record = robot.emulator.truth_record  # type: ignore[method-assign]
    return robot, camera


def serve_emulator(
    world,
    nxt: NxtConfig,
    emulator: EmulatorConfig | None = None,
    *,
    inbox: Path | None = None,
    stop=None,
    print_fn=print,
) -> None:
    """Body of ``scenebot nxt-emulator``: start the brick emulator on a pty, backed by the
    campaign's simulated ``world``, print the port path, and serve until Ctrl-C / SIGTERM.

    Args:
        world: the simulated world (:func:`scenebot.robot.factory.make_sim_world`).
        nxt: the NXT settings (port wiring; the printed geometry must match it).
        emulator: emulator settings (timing, faults).
        inbox: folder the emulated Wi-Fi card writes to (default ``nxt.camera.inbox``);
            created if missing.
        stop: a ``threading.Event`` that ends the service (tests).
        print_fn: where the port path and the settings to use are printed.
    """
    from scenebot.robot.nxt.emulator import serve

    folder = Path(inbox if inbox is not None else nxt.camera.inbox)
    folder.mkdir(parents=True, exist_ok=True)
    emu_cfg = (emulator or EmulatorConfig()).model_copy(update={"inbox": folder})
    p = world.params
    print_fn(
        "robot geometry for nxt: "
        f"wheel_radius_m={p.wheel_radius_m}, wheel_base_m={p.wheel_base_m}, "
        f"max_wheel_speed_deg_s={p.max_wheel_speed_deg_s}, camera.inbox={folder}"
    )
    serve(world, nxt, emu_cfg, stop=stop, print_fn=print_fn)
