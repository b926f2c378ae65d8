"""Campaign glue: build the NXT backends the way ``scenebot.capture`` builds the simulator."""

from __future__ import annotations

from pathlib import Path

from scenebot.robot.nxt import make_nxt_robot
from scenebot.robot.nxt.camera import NxtCamera
from scenebot.robot.nxt.config import EmulatorConfig, NxtConfig
from scenebot.robot.nxt.robot import NxtRobot


def make_nxt_backend(
    cfg,
    nxt: NxtConfig,
    *,
    emulated: bool,
    emulator: EmulatorConfig | None = None,
    inbox: Path | None = None,
    start=None,
) -> tuple[NxtRobot, NxtCamera, object | None]:
    """``(robot, camera, world)`` for ``robot: nxt`` (``world`` is None) or ``nxt-emulated``.

    Args:
        cfg: the campaign config (:class:`scenebot.config.Config`); for ``nxt-emulated`` its
            world and simulator settings build the :class:`~scenebot.sim.world.SimWorld` that
            backs the brick emulator, exactly as the ``sim`` backend builds it.
        nxt: the NXT settings.
        emulated: start the brick emulator on a pty and drive it through pyserial.
        inbox: photo inbox to use instead of ``nxt.camera.inbox`` (e.g. a folder inside the
            capture directory for the emulator, so the final move is a same-disk rename).
        emulator: emulator settings (timing, faults).
        start: ``nxt-emulated`` only: the true pose the simulated world continues from.
    """
    if inbox is not None:
        nxt = nxt.model_copy(
            update={"camera": nxt.camera.model_copy(update={"inbox": Path(inbox)})}
        )
    if not emulated:
        robot, camera = make_nxt_robot(nxt)
        return robot, camera, None
    from scenebot.capture import make_sim_backend

    _, _, world = make_sim_backend(cfg, start)
    robot, camera = make_nxt_robot(nxt, world=world, emulator=emulator)
    # like the simulator backend, log the true pose for evaluation (never used to decide)
    robot.truth_record = robot.emulator.truth_record  # type: ignore[method-assign]
    return robot, camera, world


def serve_emulator(
    cfg,
    nxt: NxtConfig,
    emulator: EmulatorConfig | None = None,
    *,
    inbox: Path | None = None,
    stop=None,
    print_fn=print,
) -> None:
    """Body of ``scenebot nxt-emulator``: build the campaign's simulated world, start the
    brick emulator on a pty, print the port path, and serve until Ctrl-C / SIGTERM.

    Args:
        cfg: the campaign config (world and simulator settings).
        nxt: the NXT settings (port wiring; the printed geometry must match it).
        emulator: emulator settings (timing, faults).
        inbox: folder the emulated Wi-Fi card writes to (default ``nxt.camera.inbox``);
            created if missing.
        stop: a ``threading.Event`` that ends the service (tests).
        print_fn: where the port path and the settings to use are printed.
    """
    from scenebot.capture import make_sim_backend
    from scenebot.robot.nxt.emulator import serve

    _, _, world = make_sim_backend(cfg)
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
