"""The observable surface: reachability, weighted sampling, visibility, cache (evaluation)."""

from __future__ import annotations

import numpy as np
import pytest

from scenebot.config import Config
from scenebot.evaluate.config import EvaluateConfig
from scenebot.evaluate.observable import (
    ObservableError,
    ObservableSurface,
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
    a, cached = load_or_compute(path, scene, sim, fast_cfg())
    assert not cached and path.is_file()
    b, cached = load_or_compute(path, scene, sim, fast_cfg())
    assert cached
    assert np.array_equal(a.observable, b.observable)
    assert np.allclose(a.points, b.points, atol=1e-6)
    assert np.array_equal(b.reachable["mask"], a.reachable["mask"])
    _, cached = load_or_compute(path, scene, sim, fast_cfg(max_incidence_deg=60.0))
    assert not cached
    loaded = ObservableSurface.load(path)
    assert loaded.meta["evaluate"]["max_incidence_deg"] == 60.0
    assert plot_observable(loaded, tmp_path / "obs.png").stat().st_size > 10_000


def test_a_start_pose_argument_overrides_the_scene(scene):
    sim = Config().sim
    with pytest.raises(ObservableError):
        observable_surface(scene, sim, fast_cfg(), start=Pose2D(1.3, 1.3, 0.0))
