"""Shared fixtures: small scenes with known geometry, fast simulator settings."""

from __future__ import annotations

import os

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")
os.environ.setdefault("MPLBACKEND", "Agg")

import pytest

from scenebot.config import Config, SimConfig
from scenebot.scene.mesh import SceneMesh
from tests.fixtures.rooms import box_room


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
