"""The backend factory: the configured robot and camera, for every stage that drives one.

``sim``: the simulated robot in the configured world. ``nxt``: a LEGO NXT on ``nxt.port``,
photos arriving in ``nxt.camera.inbox``. ``nxt-emulated``: the same driver talking, through a
pseudo-terminal, to the brick emulator, which runs on a simulated world built here and
handed to it. Stages ask this module for a backend; nothing here imports a stage.

The simulator's state between rounds belongs to the simulator backend
(:func:`scenebot.robot.sim.read_sim_state`): a capture that continues an earlier one names
the earlier capture folder, and a simulated world starts where that robot stopped.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from scenebot.config import Config
from scenebot.robot.base import Pose2D


def start_pose(scene, world_cfg, collision_map) -> Pose2D:
    """The configured start pose (``world_cfg.start``; ``world_cfg`` may be None), else the
    scene's, else the centre of the widest free space of ``collision_map`` (heading 0)."""
    if world_cfg is not None and world_cfg.start is not None:
        s = world_cfg.start
        return Pose2D(s.x, s.y, math.radians(s.theta_deg))
    if scene.start is not None:
        return scene.start
    r, c = np.unravel_index(np.argmax(collision_map.clearance), collision_map.clearance.shape)
    xy = collision_map.origin + np.array([c, r]) * collision_map.res
    return Pose2D(float(xy[0]), float(xy[1]), 0.0)


def make_sim_world(cfg: Config, start: Pose2D | None = None):
    """The :class:`~scenebot.sim.world.SimWorld` of ``cfg``'s world and simulator settings.

    ``start``: the true start pose (world frame) when the world continues an earlier round;
    default: the configured or the scene's start pose.
    """
    from scenebot.scene.loader import load_world_scene
    from scenebot.sim.obstacles import ObstacleMap
    from scenebot.sim.world import SimWorld

    scene = load_world_scene(cfg.world)
    body = cfg.sim.body
    if start is None:
        cmap = None
        if cfg.world.start is None and scene.start is None:
            cmap = ObstacleMap.build(
                scene, scene.floor_z + body.clearance_m, scene.floor_z + body.height_m
            )
        start = start_pose(scene, cfg.world, cmap)
    return SimWorld(scene, cfg.sim, start, seed=cfg.seed)


def make_sim_backend(cfg: Config, start: Pose2D | None = None):
    """(robot, camera, world) of the simulator for ``cfg`` (``start``: see
    :func:`make_sim_world`)."""
    from scenebot.robot.sim import SimCamera, SimRobot

    world = make_sim_world(cfg, start)
    return SimRobot(world), SimCamera(world), world


def make_backend(cfg: Config, capture_dir: Path, previous_capture: Path | None = None):
    """(robot, camera, world or None) of the configured ``robot`` backend.

    Args:
        cfg: the campaign config (``robot``, and the settings of that backend).
        capture_dir: the capture folder; ``nxt-emulated``'s Wi-Fi card writes to
            ``<capture>/inbox`` so photos move into ``images/`` by rename.
        previous_capture: the capture folder of the round this one continues: a simulated
            world starts where that round's robot stopped (its ``sim_state.json``); a real
            robot is where it is.
    """
    from scenebot.robot.sim import read_sim_state

    simulated = cfg.robot in ("sim", "nxt-emulated")
    start = read_sim_state(previous_capture) if simulated and previous_capture else None
    if cfg.robot == "sim":
        return make_sim_backend(cfg, start)
    from scenebot.robot.nxt.backend import make_nxt_backend

    if not simulated:
        robot, camera = make_nxt_backend(cfg.nxt)
        return robot, camera, None
    world = make_emulator_world(cfg, start)
    robot, camera = make_nxt_backend(
        cfg.nxt, world=world, emulator=cfg.nxt_emulator, inbox=Path(capture_dir) / "inbox"
    )
    return robot, camera, world


def make_emulator_world(cfg: Config, start: Pose2D | None = None):
    """The simulated world the NXT brick emulator runs on (``start``: see
    :func:`make_sim_world`).

    It is the world exactly as the ``sim`` backend builds it, whose simulated robot reads the
    compass once on creation (one draw of the world's noise): the emulated robot's photos
    stay the ones it has always taken.
    """
    _, _, world = make_sim_backend(cfg, start)
    return world
