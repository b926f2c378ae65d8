"""The observable surface: reachability, weighted sampling, visibility, cache (evaluation)."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from scenebot.config import Config
from scenebot.evaluate import observable as observable_module
from scenebot.evaluate.config import EvaluateConfig
from scenebot.evaluate.observable import (
    ObservableError,
    ObservableSurface,
    _write_atomic,
    collision_map,
    load_or_compute,
    observable_surface,
    plot_observable,
    reachable_mask,
    sample_surface_weighted,
    triangle_normals,
)
from scenebot.robot.base import Pose2D
from tests.fixtures.rooms import box_room

BOX = ((1.0, 1.0, 0.0), (1.6, 1.6, 0.5))  # top at 0.5 m: above the 0.35 m camera


def fast_cfg(**over) -> EvaluateConfig:
    return EvaluateConfig(grid_step_m=0.4, headings=6, sample_spacing_m=0.05, **over)


@pytest.fixture(scope="module")
def scene():
    return box_room(obstacles=[BOX], start=(3.0, 1.5, 0.0))


@pytest.fixture(scope="module")
def surf(scene):
    return observable_surface(scene, Config().sim, fast_cfg())


def test_weighted_samples_cover_the_area_and_lie_on_their_triangles(scene):
    pts, w, tid = sample_surface_weighted(scene.vertices, scene.triangles, 0.05, seed=1)
    normals, area = triangle_normals(scene.vertices, scene.triangles)
    assert w.sum() == pytest.approx(area.sum(), rel=1e-9)
    assert np.bincount(tid, minlength=len(area)).min() >= 1  # every triangle represented
    v0 = scene.vertices[scene.triangles[tid, 0]]
    assert np.abs(np.sum((pts - v0) * normals[tid], axis=1)).max() < 1e-9
    lo, hi = scene.bounds
    assert np.all(pts >= lo - 1e-9) and np.all(pts <= hi + 1e-9)


def test_a_closed_wall_splits_the_room_and_a_doorway_joins_it():
    sim = Config().sim
    wall = ((1.9, 0.0, 0.0), (2.1, 3.0, 2.5))
    closed = box_room(obstacles=[wall], start=(1.0, 1.5, 0.0))
    r = reachable_mask(collision_map(closed, sim), (1.0, 1.5), sim.body.radius_m)
    cmap = collision_map(closed, sim)
    assert r[cmap._cell((1.0, 1.5))] and not r[cmap._cell((3.0, 1.5))]
    door = box_room(
        obstacles=[((1.9, 0.0, 0.0), (2.1, 1.2, 2.5)), ((1.9, 2.0, 0.0), (2.1, 3.0, 2.5))],
        start=(1.0, 1.5, 0.0),
    )
    cmap = collision_map(door, sim)
    r = reachable_mask(cmap, (1.0, 1.5), sim.body.radius_m)
    assert r[cmap._cell((1.0, 1.5))] and r[cmap._cell((3.0, 1.5))]
    # never closer to geometry than the robot radius
    assert cmap.clearance[r].min() >= sim.body.radius_m


def test_a_start_inside_an_obstacle_names_the_setting(scene):
    sim = Config().sim
    with pytest.raises(ObservableError, match=r"world\.start"):
        reachable_mask(collision_map(scene, sim), (1.3, 1.3), sim.body.radius_m)


def test_what_no_reachable_camera_sees_is_not_observable(scene, surf):
    p, obs = surf.points, surf.observable
    # floor under the box and the box's top (above the camera, 0.5 m): hidden, up to the edges
    under = (p[:, 2] < 1e-6) & np.all((p[:, :2] > 1.0) & (p[:, :2] < 1.6), axis=1)
    top = (np.abs(p[:, 2] - 0.5) < 1e-6) & np.all((p[:, :2] >= 1.0) & (p[:, :2] <= 1.6), axis=1)
    assert under.sum() > 20 and top.sum() > 20
    assert not obs[under].any() and not obs[top].any()
    # the walls at camera height (+- 0.3 m) are seen from the middle of the room
    walls = (np.abs(p[:, 2] - 0.35) < 0.3) & (
        (p[:, 0] < 1e-6) | (p[:, 0] > 4 - 1e-6) | (p[:, 1] < 1e-6) | (p[:, 1] > 3 - 1e-6)
    )
    assert obs[walls].mean() > 0.97
    # the ceiling above the middle is outside the vertical field of view (23 deg up)
    ceiling_mid = (
        (p[:, 2] > 2.5 - 1e-6) & (np.abs(p[:, 0] - 2) < 0.5) & (np.abs(p[:, 1] - 1.5) < 0.5)
    )
    assert ceiling_mid.sum() > 20 and not obs[ceiling_mid].any()
    s = surf.summary()
    assert 0.3 < s["observable_fraction"] < 0.95
    assert s["observable_area_m2"] == pytest.approx(surf.weights[obs].sum())


def test_more_headings_and_a_finer_grid_never_see_less(scene, surf):
    finer = observable_surface(
        scene, Config().sim, EvaluateConfig(grid_step_m=0.25, headings=8, sample_spacing_m=0.05)
    )
    assert np.array_equal(finer.points, surf.points)  # same seed and spacing: same samples
    assert finer.observable.sum() >= surf.observable.sum() - 0.005 * len(surf.points)


def test_the_cache_is_reused_and_invalidated_by_a_setting(tmp_path, scene, surf):
    path = tmp_path / "obs.npz"
    sim = Config().sim
    a, origin = load_or_compute(path, scene, sim, fast_cfg(cache_dir=""))  # the file alone
    assert origin.source == "computed" and not origin.cached and path.is_file()
    b, origin = load_or_compute(path, scene, sim, fast_cfg(cache_dir=""))
    assert origin.source == "output" and origin.cached
    assert np.array_equal(a.observable, b.observable)
    assert np.allclose(a.points, b.points, atol=1e-6)
    assert np.array_equal(b.reachable["mask"], a.reachable["mask"])
    _, origin = load_or_compute(path, scene, sim, fast_cfg(max_incidence_deg=60.0, cache_dir=""))
    assert origin.source == "computed"
    loaded = ObservableSurface.load(path)
    assert loaded.meta["evaluate"]["max_incidence_deg"] == 60.0
    assert plot_observable(loaded, tmp_path / "obs.png").stat().st_size > 10_000


def test_a_start_pose_argument_overrides_the_scene(scene):
    sim = Config().sim
    with pytest.raises(ObservableError):
        observable_surface(scene, sim, fast_cfg(), start=Pose2D(1.3, 1.3, 0.0))


def _same_surface(a: ObservableSurface, b: ObservableSurface) -> None:
    assert np.array_equal(a.points, b.points) and np.array_equal(a.weights, b.weights)
    assert np.array_equal(a.observable, b.observable) and np.array_equal(a.triangle, b.triangle)
    assert np.array_equal(a.positions, b.positions)
    assert np.array_equal(a.reachable["mask"], b.reachable["mask"])
    assert a.meta == b.meta


def _no_computing(monkeypatch) -> None:
    def boom(*args, **kwargs):
        raise AssertionError("the observable surface was computed again")

    monkeypatch.setattr(observable_module, "observable_surface", boom)


def test_a_second_campaign_reads_the_shared_cache(tmp_path, scene, monkeypatch, caplog):
    """Another campaign's folder, same scene and settings: the shared cache's file is copied
    to its output, nothing is computed, and the log names the file and the key's hash."""
    sim, ecfg = Config().sim, fast_cfg(cache_dir=str(tmp_path / "cache"))
    first = tmp_path / "campaign_a" / "eval" / "observable_surface.npz"
    _, origin_a = load_or_compute(first, scene, sim, ecfg)
    assert origin_a.source == "computed"
    shared = origin_a.cache_file
    assert shared.parent == tmp_path / "cache" / "observable"
    assert shared.name == f"observable_surface-v2-{origin_a.key_hash}.npz"
    assert len(origin_a.key_hash) == 64 and shared.is_file()
    assert not list(shared.parent.glob("*.tmp")) and not list(first.parent.glob("*.tmp"))

    _no_computing(monkeypatch)
    second = tmp_path / "campaign_b" / "eval" / "observable_surface.npz"
    with caplog.at_level(logging.INFO, logger=observable_module.__name__):
        b, origin_b = load_or_compute(second, scene, sim, ecfg)
    assert origin_b.source == "cache" and origin_b.cached
    assert origin_b.key_hash == origin_a.key_hash and origin_b.cache_file == shared
    _same_surface(ObservableSurface.load(first), b)
    _same_surface(ObservableSurface.load(second), b)
    # a copy with its own time stamp (Snakemake touches outputs; a hard link would touch all)
    assert second.stat().st_ino != shared.stat().st_ino and second.stat().st_nlink == 1
    said = caplog.text
    assert "from the shared cache" in said and str(shared) in said and origin_a.key_hash in said
    assert origin_b.as_dict() == {
        "cached": True, "source": "cache", "key_hash": origin_a.key_hash,
        "cache_file": str(shared),
    }  # fmt: skip


def test_a_changed_setting_misses_the_shared_cache(tmp_path, scene):
    sim, cache = Config().sim, tmp_path / "cache"
    _, origin = load_or_compute(tmp_path / "a.npz", scene, sim, fast_cfg(cache_dir=str(cache)))
    other = fast_cfg(cache_dir=str(cache), max_incidence_deg=60.0)
    _, changed = load_or_compute(tmp_path / "b.npz", scene, sim, other)
    assert changed.source == "computed"
    assert changed.key_hash != origin.key_hash and changed.cache_file != origin.cache_file
    assert sorted((cache / "observable").iterdir()) == sorted(
        [origin.cache_file, changed.cache_file]
    )
    assert ObservableSurface.load(changed.cache_file).meta["evaluate"]["max_incidence_deg"] == 60
    # another start pose is another key too
    _, moved = load_or_compute(tmp_path / "c.npz", scene, sim, fast_cfg(cache_dir=str(cache)),
                               start=Pose2D(3.0, 2.0, 0.0))  # fmt: skip
    assert moved.source == "computed" and moved.key_hash != origin.key_hash


def test_an_empty_cache_dir_turns_the_shared_cache_off(tmp_path, scene, monkeypatch):
    env_cache = tmp_path / "from_env"
    monkeypatch.setenv("SCENEBOT_CACHE", str(env_cache))
    sim = Config().sim
    for name in ("a", "b"):  # two campaigns: both compute
        _, origin = load_or_compute(tmp_path / f"{name}.npz", scene, sim, fast_cfg(cache_dir=""))
        assert origin.source == "computed" and origin.cache_file is None
    assert not env_cache.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.npz", "b.npz"]
    # SCENEBOT_CACHE="" (and no setting) turns it off too
    monkeypatch.setenv("SCENEBOT_CACHE", "")
    assert fast_cfg().cache_folder() is None


def test_a_corrupt_shared_cache_file_is_recomputed_with_a_warning(tmp_path, scene, caplog):
    sim, ecfg = Config().sim, fast_cfg(cache_dir=str(tmp_path / "cache"))
    a, origin = load_or_compute(tmp_path / "a.npz", scene, sim, ecfg)
    shared = origin.cache_file
    data = shared.read_bytes()
    shared.write_bytes(data[: len(data) // 2])  # a half-written file (a killed copy)
    with caplog.at_level(logging.WARNING, logger=observable_module.__name__):
        b, again = load_or_compute(tmp_path / "b.npz", scene, sim, ecfg)
    assert again.source == "computed"
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1 and str(shared) in warnings[0].getMessage()
    assert np.array_equal(a.observable, b.observable)
    # the file was replaced: the next campaign reads it
    _, third = load_or_compute(tmp_path / "c.npz", scene, sim, ecfg)
    assert third.source == "cache"
    _same_surface(ObservableSurface.load(tmp_path / "c.npz"), ObservableSurface.load(shared))
    # not a zip file at all
    shared.write_bytes(b"not an npz file")
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger=observable_module.__name__):
        _, fourth = load_or_compute(tmp_path / "d.npz", scene, sim, ecfg)
    assert fourth.source == "computed" and str(shared) in caplog.text


def test_a_campaign_file_from_before_the_shared_cache_fills_it(tmp_path, scene):
    sim = Config().sim
    old = tmp_path / "old.npz"
    load_or_compute(old, scene, sim, fast_cfg(cache_dir=""))
    ecfg = fast_cfg(cache_dir=str(tmp_path / "cache"))
    _, origin = load_or_compute(old, scene, sim, ecfg)
    assert origin.source == "output" and origin.cache_file.is_file()
    _, new = load_or_compute(tmp_path / "new.npz", scene, sim, ecfg)
    assert new.source == "cache"


def test_an_interrupted_write_leaves_no_file(tmp_path):
    def half(fh):
        fh.write(b"half of it")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        _write_atomic(tmp_path / "x.npz", half)
    assert list(tmp_path.iterdir()) == []


def test_the_cache_folder_follows_the_setting_then_the_environment(tmp_path, monkeypatch):
    monkeypatch.setenv("SCENEBOT_CACHE", str(tmp_path / "env"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert EvaluateConfig(cache_dir=str(tmp_path / "set")).cache_folder() == tmp_path / "set"
    assert EvaluateConfig(cache_dir="~/c").cache_folder() == tmp_path / "home" / "c"
    monkeypatch.chdir(tmp_path)
    assert EvaluateConfig(cache_dir="rel").cache_folder() == tmp_path / "rel"
    assert EvaluateConfig(cache_dir="").cache_folder() is None
    assert EvaluateConfig().cache_folder() == tmp_path / "env"
    monkeypatch.delenv("SCENEBOT_CACHE")
    assert EvaluateConfig().cache_folder() == tmp_path / "xdg" / "scenebot"
    monkeypatch.setenv("XDG_CACHE_HOME", "relative/xdg")  # not absolute: ignored (XDG spec)
    assert EvaluateConfig().cache_folder() == tmp_path / "home" / ".cache" / "scenebot"
    monkeypatch.delenv("XDG_CACHE_HOME")
    assert EvaluateConfig().cache_folder() == tmp_path / "home" / ".cache" / "scenebot"


def test_the_tests_never_use_the_users_cache(shared_cache):
    """tests/conftest.py points SCENEBOT_CACHE at the session's shared folder."""
    from pathlib import Path

    assert EvaluateConfig().cache_folder() == shared_cache
    assert Path("~/.cache").expanduser() not in shared_cache.parents
