"""The built-in ``flat`` scene: deterministic, floor found, rooms connected, capture runs."""

from __future__ import annotations

import numpy as np
import pytest

from scenebot.config import Config
from scenebot.evaluate.observable import collision_map, reachable_mask
from scenebot.scene.flat import CORRIDOR_WALL_Y, FLAT_D_M, FLAT_W_M, PARTITION_X, flat
from scenebot.scene.loader import detect_floor_z


@pytest.fixture(scope="module")
def scene():
    return flat(7)


def test_the_same_seed_gives_the_same_flat_and_another_seed_another(scene):
    again = flat(7)
    assert np.array_equal(scene.vertices, again.vertices)
    assert np.array_equal(scene.triangles, again.triangles)
    assert [m.name for m in scene.materials] == [m.name for m in again.materials]
    assert all(
        np.array_equal(a.texture, b.texture)
        for a, b in zip(scene.materials, again.materials, strict=True)
    )
    assert scene.start == again.start
    other = flat(8)
    assert other.vertices.shape != scene.vertices.shape or not np.allclose(
        other.vertices, scene.vertices
    )


def test_the_floor_is_detected_and_the_flat_is_closed(scene):
    assert detect_floor_z(scene.vertices, scene.triangles) == pytest.approx(0.0, abs=1e-6)
    lo, hi = scene.bounds
    assert np.allclose(lo, [0, 0, 0]) and np.allclose(hi, [FLAT_W_M, FLAT_D_M, 2.5])
    # textured like the office: every material has a texture, most are real images
    assert sum(m.texture.shape[0] > 1 for m in scene.materials) >= 20


@pytest.mark.parametrize("seed", [7, 1, 2, 3])
def test_both_rooms_and_the_corridor_are_one_reachable_region(seed):
    sc = flat(seed)
    sim = Config().sim
    cmap = collision_map(sc, sim)
    radius = sim.body.radius_m
    assert cmap.clearance_at((sc.start.x, sc.start.y)) >= radius + 0.2  # room to turn
    reach = reachable_mask(cmap, (sc.start.x, sc.start.y), radius)
    py0, py1 = CORRIDOR_WALL_Y
    px0, px1 = PARTITION_X
    h, w = reach.shape
    xy = cmap.origin + np.stack(np.meshgrid(np.arange(w), np.arange(h)), -1) * cmap.res
    living = reach & (xy[..., 0] < px0) & (xy[..., 1] < py0)
    bedroom = reach & (xy[..., 0] > px1) & (xy[..., 1] < py0)
    corridor = reach & (xy[..., 1] > py1)
    for name, region in (("living room", living), ("bedroom", bedroom), ("corridor", corridor)):
        area = region.sum() * cmap.res**2
        assert area > 1.5, f"seed {seed}: only {area:.2f} m^2 of the {name} is reachable"
    # the rooms connect only through the corridor: the partition is solid
    on_partition = (np.abs(xy[..., 0] - (px0 + px1) / 2) < 0.05) & (xy[..., 1] < py0)
    assert not reach[on_partition].any()


def test_a_capture_of_20_photos_runs_in_the_flat(tmp_path, scene):
    from scenebot.capture.stage import run_capture
    from scenebot.capturelog import photo_records

    cfg = Config.model_validate({
        "world": {"builtin": "flat", "seed": 7},  # the scene fixture's
        "sim": {"camera": {"width": 80, "height": 60}},
        "exploration": {"photos": 20},
    })  # fmt: skip
    summary = run_capture(cfg, tmp_path / "capture", progress=False)
    assert summary["photos"] == 20
    photos = photo_records(tmp_path / "capture" / "log.jsonl")
    assert len(photos) == 20
    sim = Config().sim
    cmap = collision_map(scene, sim)
    reach = reachable_mask(cmap, (scene.start.x, scene.start.y), sim.body.radius_m - 0.02)
    for p in photos:
        t = p["truth"]["robot"]
        assert reach[cmap._cell((t["x"], t["y"]))]
        assert p["truth"]["center"][2] == pytest.approx(sim.camera.height_m)
    assert summary["max_penetration_m"] < 0.02


@pytest.mark.slow
def test_the_observable_surface_of_the_flat_spans_both_rooms_and_the_corridor(scene):
    from scenebot.evaluate.config import EvaluateConfig
    from scenebot.evaluate.observable import observable_surface

    ecfg = EvaluateConfig(grid_step_m=0.5, headings=6, sample_spacing_m=0.1)
    surf = observable_surface(scene, Config().sim, ecfg)
    p, obs, w = surf.points, surf.observable, surf.weights
    py0, py1 = CORRIDOR_WALL_Y
    px0, px1 = PARTITION_X
    walls = (p[:, 2] > 0.2) & (p[:, 2] < 0.6)  # a band around the camera's height
    regions = {
        "living room": walls & (p[:, 0] < px0) & (p[:, 1] < py0),
        "bedroom": walls & (p[:, 0] > px1) & (p[:, 1] < py0),
        "corridor": walls & (p[:, 1] > py1),
    }
    for name, m in regions.items():
        seen = w[m & obs].sum()
        assert seen > 3.0, f"only {seen:.2f} m^2 of the {name}'s walls are observable"
    s = surf.summary()
    assert 0.3 < s["observable_fraction"] < 0.8
    # the tops of the door leaves (2 m, far above the camera) are hidden
    top = (np.abs(p[:, 2] - 2.0) < 1e-6) & (p[:, 1] > py0 - 0.84) & (p[:, 1] < py0)
    assert top.any() and not obs[top].any()
