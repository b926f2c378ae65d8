"""Shared fixtures: small scenes with known geometry, fast simulator settings."""

from __future__ import annotations

import os

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")
os.environ.setdefault("MPLBACKEND", "Agg")

import pytest

from scenebot.config import Config, SimConfig
from scenebot.scene.mesh import SceneMesh
from tests.fixtures.rooms import box_room


@pytest.fixture(scope="session", autouse=True)
def shared_cache(tmp_path_factory):
    """The cache shared by campaigns (``evaluate.cache_dir``) in a folder of this test
    session that its xdist workers share, never the user's ~/.cache: ``SCENEBOT_CACHE`` for
    the whole session, inherited by the Snakemake runs, so that the workflow tests compute
    the office's observable surface once per set of settings."""
    from tests.fixtures.workflow import _shared_dir

    folder = _shared_dir(tmp_path_factory) / "scenebot-cache"
    old = os.environ.get("SCENEBOT_CACHE")
    os.environ["SCENEBOT_CACHE"] = str(folder)
    yield folder
    if old is None:
        os.environ.pop("SCENEBOT_CACHE", None)
    else:
        os.environ["SCENEBOT_CACHE"] = old


@pytest.fixture(scope="session")
def room() -> SceneMesh:
    return box_room()


@pytest.fixture
def workdir(tmp_path):
    """A folder with the small office config (``tests.fixtures.workflow.SMALL``) for
    Snakemake runs."""
    import yaml

    from tests.fixtures.workflow import SMALL

    (tmp_path / "config.yaml").write_text(yaml.safe_dump(SMALL))
    return tmp_path


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


def _gpu_arch() -> str | None:
    """The GPU arch taichi starts on here (``cuda`` or ``vulkan``), or None; asked in a
    subprocess so that this process's taichi stays unstarted."""
    import subprocess
    import sys

    code = (
        "import taichi as ti; ti.init(arch=[ti.cuda, ti.vulkan], log_level=ti.ERROR); "
        "print(ti.lang.impl.current_cfg().arch.name)"
    )
    try:
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             timeout=120, check=False)  # fmt: skip
    except subprocess.TimeoutExpired:
        return None
    arch = out.stdout.strip().splitlines()[-1] if out.stdout.strip() else ""
    return arch if arch in ("cuda", "vulkan") else None


# The files that take minutes, longest first (seconds in CI's run at 0a4f1e8, two workers on
# the 2-core reference machine): handed out first, in this order, the longest start at once.
LONGEST_FILES = (
    "test_suite.py",  # a two-scene mini-suite: 1,477 s under load 6-14 (not yet run in CI)
    "test_workflow_canned.py",  # 396
    "test_round0_registration.py",  # 269
    "test_cluster.py",  # 246
    "test_sfm_stage.py",  # about 140 in all: 16 tests, a module's map
    "test_workflow_photos.py",  # 130; now one campaign, shared with test_cluster.py
    "test_guide_workflow.py",  # 215 under load (not yet run in CI)
    "test_follow_sim.py",  # 98 + two short tests
    "test_tour_photos.py",  # 95 + four short tests
)


def _slow_files_first(items: list) -> None:
    """Files that hold a ``slow`` test run first, the minutes-long ones of ``LONGEST_FILES``
    first of all and longest first, each file's tests kept together and in order.

    With ``pytest -n 2 --dist loadfile --no-loadscope-reorder`` (the CI command; without the
    last option xdist hands out the files with the most tests first) a file is one unit of
    work, handed out in this order: the minutes-long workflow tests start while the other
    worker drains the many short files, instead of starting last with one worker idle beside
    them (longest processing time first). Without xdist the order changes nothing but the
    order."""
    slow_files = {item.path for item in items if item.get_closest_marker("slow")}
    rank = {name: i for i, name in enumerate(LONGEST_FILES)}

    def key(item) -> tuple[int, int]:
        if item.path not in slow_files:
            return (2, 0)
        return (0, rank[item.path.name]) if item.path.name in rank else (1, 0)

    items.sort(key=key)  # stable: keeps the order within


@pytest.hookimpl(trylast=True)  # after -m has deselected: no GPU probe when no gpu test runs
def pytest_collection_modifyitems(config, items):
    """Tests marked ``gpu`` are skipped, saying so, where taichi finds no CUDA or Vulkan
    device (they would otherwise fail on the CPU fallback)."""
    _slow_files_first(items)
    gpu_items = [item for item in items if item.get_closest_marker("gpu")]
    if not gpu_items or _gpu_arch() is not None:
        return
    skip = pytest.mark.skip(reason="no CUDA or Vulkan device for taichi on this machine")
    for item in gpu_items:
        item.add_marker(skip)
