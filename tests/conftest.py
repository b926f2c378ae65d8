"""Shared fixtures: small scenes with known geometry, fast simulator settings."""

from __future__ import annotations

import os

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")
os.environ.setdefault("MPLBACKEND", "Agg")

import numpy as np
import pytest

from scenebot.config import Config, SimConfig
from scenebot.robot.base import Pose2D
from scenebot.scene import textures as tx
from scenebot.scene.mesh import Material, SceneBuilder, SceneMesh


def box_room(
    size=(4.0, 3.0), height=2.5, obstacles=(), name="boxroom", start=(2.0, 1.5, 0.0)
) -> SceneMesh:
    """A textured rectangular room [0, W] x [0, D] with optional boxes (lo, hi) inside."""
    rng = np.random.default_rng(3)
    W, D = size
    b = SceneBuilder(name)
    floor = b.material(Material("carpet", tx.carpet(rng, 128)))
    wall = b.material(Material("poster", tx.poster(rng, 128, 128)))
    box = b.material(Material("cardboard", tx.cardboard(rng, 128)))
    b.quad([0, 0, 0], [W, 0, 0], [0, D, 0], floor, uv_size=(0.5, 0.5))
    b.quad([0, 0, height], [0, D, 0], [W, 0, 0], floor, uv_size=(0.5, 0.5))
    for o, u in (([0, 0, 0], [W, 0, 0]), ([W, 0, 0], [0, D, 0]), ([W, D, 0], [-W, 0, 0]),
                 ([0, D, 0], [0, -D, 0])):  # fmt: skip
        b.quad(o, u, [0, 0, height], wall, uv_size=(1.0, 1.0))
    for lo, hi in obstacles:
        b.box(lo, hi, box, (0.5, 0.5))
    b.light([W / 2, D / 2, height - 0.1])
    return b.build(start=Pose2D(*start))


@pytest.fixture(scope="session")
def room() -> SceneMesh:
    return box_room()


@pytest.fixture
def sim_cfg() -> SimConfig:
    """Simulator settings with a tiny camera (fast) and default physics."""
    cfg = Config().sim.model_copy(deep=True)
    cfg.camera.width, cfg.camera.height = 64, 48
    cfg.camera.antialias = False
    return cfg


@pytest.fixture
def no_noise_cfg(sim_cfg) -> SimConfig:
    """Simulator settings without slip or sensor noise (exact kinematics)."""
    sim_cfg.slip.drive = sim_cfg.slip.drive_noise = 0.0
    sim_cfg.slip.turn = sim_cfg.slip.turn_noise = 0.0
    sim_cfg.slip.heading_drift_deg_per_m = 0.0
    sim_cfg.sensors.compass_noise_deg = 0.0
    sim_cfg.sensors.ultrasonic_noise_cm = 0.0
    return sim_cfg
