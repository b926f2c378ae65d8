"""The generated ``rooms`` scenes: deterministic, within their ranges, closed, the start clear,
every free spot reachable, the families of seeds 1-8 as documented, textured photos."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from scenebot.config import Config
from scenebot.evaluate.observable import collision_map, reachable_mask
from scenebot.scene.loader import detect_floor_z
from scenebot.scene.rooms import (
    DRIVE_UNDER,
    FLOOR_FAMILIES,
    KINDS,
    WALL_FAMILIES,
    describe,
    room_plan,
    rooms,
)

SEEDS = range(1, 13)


@pytest.fixture(scope="module", params=SEEDS)
def room(request):
    """(seed, plan, scene) of each seed, built once."""
    return request.param, room_plan(request.param), rooms(request.param)


def test_the_same_seed_gives_the_same_room_and_another_seed_another():
    a, again, other = rooms(4), rooms(4), rooms(5)
    for field in ("vertices", "triangles", "uvs", "material_ids", "lights"):
        assert np.array_equal(getattr(a, field), getattr(again, field)), field
    assert [m.name for m in a.materials] == [m.name for m in again.materials]
    assert all(
        np.array_equal(m.texture, n.texture)
        for m, n in zip(a.materials, again.materials, strict=True)
    )
    assert a.start == again.start
    assert describe(4) == room_plan(4).describe()  # the plan alone gives the same room
    assert other.vertices.shape != a.vertices.shape or not np.allclose(other.vertices, a.vertices)


def test_sizes_heights_and_furniture_are_in_their_ranges(room):
    _, plan, scene = room
    d = plan.describe()
    assert d["kind"] in KINDS
    assert set(d["walls"]) <= set(WALL_FAMILIES) and set(d["floors"]) <= set(FLOOR_FAMILIES)
    assert 2.4 <= plan.height_m <= 3.0
    lo, hi = scene.bounds
    assert np.allclose(lo, 0.0) and hi[2] == pytest.approx(plan.height_m)
    assert detect_floor_z(scene.vertices, scene.triangles) == pytest.approx(0.0, abs=1e-6)
    for z in plan.zones:
        xs = [v for r in z.rects for v in (r[0], r[2])]
        ys = [v for r in z.rects for v in (r[1], r[3])]
        w, d_ = max(xs) - min(xs), max(ys) - min(ys)
        if z.name.startswith("room"):  # a room's bounding box: 3 x 3 to 8 x 6 m
            assert min(w, d_) >= 3.0 - 1e-9 and max(w, d_) <= 8.0 + 1e-9 and min(w, d_) <= 6.0
        else:  # a corridor or a doorway: the robot (0.30 m) passes
            assert min(w, d_) >= 0.8 or z.name == "doorway"
            assert max(w, d_) >= 0.8
    assert 3 <= len(plan.items) <= 10, d["furniture"]
    heights = {round(it.height_m, 1) for it in plan.items}
    assert len(heights) >= 2  # varied heights


def test_the_start_pose_is_clear_for_circles_of_photos(room):
    seed, _, scene = room
    sim = Config().sim
    cmap = collision_map(scene, sim)
    # room to turn on the spot with the camera ahead of the axis (as the flat's test asks)
    assert cmap.clearance_at((scene.start.x, scene.start.y)) >= sim.body.radius_m + 0.2, seed


def _directions(n: int) -> np.ndarray:
    """(n, 3) unit vectors spread evenly over the sphere (a Fibonacci lattice)."""
    i = np.arange(n) + 0.5
    polar, azimuth = np.arccos(1 - 2 * i / n), np.pi * (1 + 5**0.5) * i
    return np.stack([np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar),
                     np.cos(polar)], axis=1)  # fmt: skip


def test_every_room_is_closed(room):
    """Rays from the start and from the middle of every space, at the camera's height and
    higher, all hit the room (no gap a camera could look out of) inside its bounds."""
    import open3d as o3d

    from scenebot.dense.evaluate import mesh_raycaster

    seed, plan, scene = room
    caster = mesh_raycaster(scene.vertices, scene.triangles)
    dirs = _directions(3000)
    origins = [(scene.start.x, scene.start.y, 0.35)]
    for z in plan.zones:
        for x0, y0, x1, y1 in z.rects:
            origins += [((x0 + x1) / 2, (y0 + y1) / 2, h) for h in (0.35, 1.6)]
    x0, y0, x1, y1 = plan.bounds
    for o in origins:
        rays = np.hstack([np.broadcast_to(np.asarray(o, float), dirs.shape), dirs])
        t = caster.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))["t_hit"].numpy()
        assert np.isfinite(t).all(), f"seed {seed}: a ray from {o} leaves the room"
        p = np.asarray(o) + dirs * t[:, None]
        assert (p[:, 0] > x0 - 0.01).all() and (p[:, 0] < x1 + 0.01).all()
        assert (p[:, 1] > y0 - 0.01).all() and (p[:, 1] < y1 + 0.01).all()
        assert (p[:, 2] > -0.01).all() and (p[:, 2] < plan.height_m + 0.01).all()


def test_all_free_space_is_reachable_from_the_start(room):
    seed, plan, scene = room
    sim = Config().sim
    radius = sim.body.radius_m
    cmap = collision_map(scene, sim)
    reach = reachable_mask(cmap, (scene.start.x, scene.start.y), radius)
    cut_off = (cmap.clearance >= radius) & ~reach
    assert cut_off.sum() * cmap.res**2 < 0.005, f"seed {seed}: free floor out of reach"
    h, w = reach.shape
    xy = cmap.origin + np.stack(np.meshgrid(np.arange(w), np.arange(h)), -1) * cmap.res
    for z in plan.zones:  # every space is entered: two rooms are joined
        inside = np.zeros_like(reach)
        for x0, y0, x1, y1 in z.rects:
            inside |= (xy[..., 0] > x0) & (xy[..., 0] < x1) & (xy[..., 1] > y0) & (xy[..., 1] < y1)
        share = (reach & inside).sum() * cmap.res**2 / z.area_m2
        assert share > (0.3 if z.name.startswith("room") else 0.1), (seed, z.name, share)
    for it in plan.items:  # beds, tables, desks and chairs stand on legs: it drives under
        if it.kind in DRIVE_UNDER:
            x0, y0, x1, y1 = it.rect
            assert reach[cmap._cell(((x0 + x1) / 2, (y0 + y1) / 2))], (seed, it)


def test_seeds_1_to_8_cover_the_families_the_suite_needs():
    rooms_1_8 = [describe(seed) for seed in range(1, 9)]
    kinds = [d["kind"] for d in rooms_1_8]
    walls = {w for d in rooms_1_8 for w in d["walls"]}
    floors = {f for d in rooms_1_8 for f in d["floors"]}
    assert "L" in kinds and "rect" in kinds
    assert any(k.startswith("two rooms") for k in kinds)
    assert {"paint", "wallpaper"} <= walls  # plain paint and repeating wallpaper
    assert walls == set(WALL_FAMILIES) and floors == set(FLOOR_FAMILIES)
    furniture = {f for d in rooms_1_8 for f in d["furniture"]}
    assert {"bed", "table", "desk", "bookcase", "sofa", "box"} <= furniture


@pytest.mark.parametrize("seed", [1, 7])
def test_photos_from_the_start_pose_are_textured(seed):
    """The simulator, given ``world: {builtin: rooms, seed}``, renders textured photos at the
    start pose: a circle of four (plain paint; tiles) has features to match."""
    from scenebot.robot.base import Pose2D
    from scenebot.robot.factory import make_sim_world
    from scenebot.sim.world import SimWorld

    cfg = Config.model_validate({"world": {"builtin": "rooms", "seed": seed}})
    world = make_sim_world(cfg)  # the scene the configured world names, at its start pose
    start = world.truth_pose
    sift = cv2.SIFT_create()
    keypoints = []
    for k in range(4):
        pose = Pose2D(start.x, start.y, start.theta + k * np.pi / 2)
        img = SimWorld(world.scene, cfg.sim, pose, cfg.seed, renderer=world.renderer).render()
        assert img.shape == (480, 640, 3) and img.std() > 10  # not blank
        keypoints.append(len(sift.detect(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY), None)))
    assert sum(keypoints) >= 400 and max(keypoints) >= 150, keypoints


def test_a_capture_of_20_photos_runs_in_two_rooms(tmp_path):
    from scenebot.capture.stage import run_capture
    from scenebot.capturelog import photo_records

    settings = {"world": {"builtin": "rooms", "seed": 4}, "exploration": {"photos": 20},
                "sim": {"camera": {"width": 80, "height": 60}}}  # fmt: skip
    cfg = Config.model_validate(settings)
    summary = run_capture(cfg, tmp_path / "capture", progress=False)
    assert summary["photos"] == 20
    photos = photo_records(tmp_path / "capture" / "log.jsonl")
    scene = rooms(4)
    cmap = collision_map(scene, cfg.sim)
    reach = reachable_mask(cmap, (scene.start.x, scene.start.y), cfg.sim.body.radius_m - 0.02)
    for p in photos:
        t = p["truth"]["robot"]
        assert reach[cmap._cell((t["x"], t["y"]))]
    assert summary["max_penetration_m"] < 0.02


def test_the_gallery_draws_the_rooms_from_above(tmp_path, capsys):
    from PIL import Image

    from scenebot.cli import main
    from scenebot.scene.gallery import parse_seeds

    assert parse_seeds("1-3,7") == [1, 2, 3, 7]
    out = tmp_path / "rooms.png"
    assert main(["rooms-gallery", "--seeds", "4,7", "--out", str(out)]) == 0
    img = np.asarray(Image.open(out).convert("L"))
    assert img.shape[1] > 1.5 * img.shape[0] and img.std() > 20  # two panels side by side
    printed = capsys.readouterr().out.splitlines()
    assert '"kind": "two rooms, doorway"' in printed[1] and '"seed": 7' in printed[2]
