"""Path following in the simulated office (SimRobot physics with slip, bumpers, stall).

The fast test localizes with an oracle (the simulator's true camera pose plus noise; a test
double standing in for visual localization, never part of the follower). The slow test
localizes for real: pycolmap SIFT photos matched against a map made from rendered reference
photos back-projected with the renderer's depth.
"""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import pycolmap
import pytest

from scenebot.capture.follow import FollowConfig, PathFollower
from scenebot.config import SimConfig
from scenebot.localize import LocalizationMap, LocalizeConfig, localize
from scenebot.localize.features import extract_sift, load_gray
from scenebot.localize.index import MapDescriptors
from scenebot.localize.locate import PoseEstimate
from scenebot.plan import PlanConfig, build_navgrid
from scenebot.plan.path import GridPlanner
from scenebot.robot.base import Camera
from scenebot.robot.sim import SimCamera, SimRobot
from scenebot.scene.office import office
from scenebot.sim.renderer import look_rotation
from scenebot.sim.world import SimWorld


@pytest.fixture(scope="module")
def scene():
    return office(7)


def _mesh_points(scene, n, seed=0):
    """Points spread uniformly over the scene's triangles (stand-in for the sparse map)."""
    rng = np.random.default_rng(seed)
    tri = scene.vertices[scene.triangles]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    k = rng.choice(len(tri), n, p=area / area.sum())
    u, v = rng.random((2, n))
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    t = tri[k]
    return t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])


def _planner(scene, cfg: SimConfig, skip_materials: tuple[str, ...] = ()):
    """Grid in the world frame shifted so the camera plane is z = 0 (the map convention).

    ``skip_materials``: surfaces left out of the map (objects the map missed)."""
    if skip_materials:
        keep = np.array(
            [not scene.materials[m].name.startswith(skip_materials) for m in scene.material_ids]
        )
        scene = dataclasses.replace(
            scene,
            triangles=scene.triangles[keep],
            uvs=scene.uvs[keep],
            material_ids=scene.material_ids[keep],
        )
    pts = _mesh_points(scene, 60000)
    cam_z = scene.floor_z + cfg.camera.height_m
    pts[:, 2] -= cam_z
    lo, hi = scene.bounds
    pcfg = PlanConfig(
        obstacle_z_min_m=scene.floor_z + cfg.body.clearance_m + 0.02 - cam_z,
        obstacle_z_max_m=scene.floor_z + cfg.body.height_m - cam_z,
        margin_m=0.0,
        inflate_m=cfg.body.radius_m + 0.03,
        lethal_points=2.0,
    )
    grid = build_navgrid(pts, np.array([lo[:2], hi[:2]]), pcfg)
    return GridPlanner(grid, pcfg.simplify_factor), cam_z


class NoPhotoCamera(Camera):
    def capture(self, dest, timeout_s=None):
        return dest


class Oracle:
    def __init__(self, world, cam_z, seed=0):
        self.world, self.cam_z = world, cam_z
        self.rng = np.random.default_rng(seed)

    def __call__(self, path):
        R, c = self.world.camera_pose()
        th = math.atan2(R[2, 1], R[2, 0]) + math.radians(self.rng.normal(0, 0.3))
        c = c - [0, 0, self.cam_z] + np.r_[self.rng.normal(0, 0.01, 2), 0.0]
        R2 = look_rotation(th)
        return PoseEstimate(R2, -R2 @ c, 500.0, 1000, 400, 300, 0.8, "oracle")


def _free_goals(world, planner, start, n, rng):
    goals = []
    while len(goals) < n:
        lo, hi = world.scene.bounds
        xy = rng.uniform(lo[:2] + 0.4, hi[:2] - 0.4)
        if world.collision_map.clearance_at(xy) < 0.45:
            continue
        if np.hypot(*(xy - start)) < 1.0:
            continue
        if hasattr(planner(start, xy), "waypoints_xy"):
            goals.append(xy)
            start = xy
    return goals


def test_follow_in_the_office_reaches_goals_and_never_drives_through_geometry(scene, tmp_path):
    cfg = SimConfig()
    world = SimWorld(scene, cfg, scene.start, seed=3)
    robot = SimRobot(world)
    planner, cam_z = _planner(scene, cfg)
    fcfg = FollowConfig(camera_forward_m=cfg.camera.forward_offset_m)
    follower = PathFollower(
        robot,
        NoPhotoCamera(),
        Oracle(world, cam_z),
        planner,
        fcfg,
        tmp_path,
        truth=world.truth_record,
    )
    rng = np.random.default_rng(1)
    goals = _free_goals(world, planner, np.array([scene.start.x, scene.start.y]), 4, rng)
    reached = 0
    for i, g in enumerate(goals):
        res = follower.go_to(g, goal_index=i)
        p = world.truth_pose
        err = math.hypot(p.x - g[0], p.y - g[1])
        reached += res.reached and err < 0.10
    assert reached == len(goals)
    assert world.max_penetration_m < 0.02


def test_box_missing_from_the_map_is_bumped_and_driven_around(scene, tmp_path):
    cfg = SimConfig()
    world = SimWorld(scene, cfg, scene.start, seed=5)
    planner, cam_z = _planner(scene, cfg, skip_materials=("cardboard",))
    box_lo, box_hi = np.array([4.13, 2.74]), np.array([4.71, 3.33])  # cardboard_36
    start, goal = np.array([scene.start.x, scene.start.y]), np.array([5.2, 3.05])
    assert world.collision_map.clearance_at(goal) > 0.3
    # the straight route crosses the box, and the map does not know it
    seg = start + np.linspace(0, 1, 200)[:, None] * (goal - start)
    assert np.any(np.all((seg > box_lo) & (seg < box_hi), axis=1))
    # ... and so the first planned path runs into it
    wp = planner(start, goal).waypoints_xy
    t = np.linspace(0, 1, 50)[:, None]
    samples = np.concatenate([a + t * (b - a) for a, b in itertools.pairwise(wp)])
    assert np.any(np.all((samples > box_lo - 0.1) & (samples < box_hi + 0.1), axis=1))
    follower = PathFollower(
        SimRobot(world),
        NoPhotoCamera(),
        Oracle(world, cam_z),
        planner,
        FollowConfig(camera_forward_m=cfg.camera.forward_offset_m),
        tmp_path,
    )
    res = follower.go_to(goal)
    p = world.truth_pose
    assert res.reached, res.reason
    assert res.obstacles >= 1 and res.replans == res.obstacles
    assert math.hypot(p.x - goal[0], p.y - goal[1]) < 0.10
    assert world.max_penetration_m < 0.02


@pytest.mark.slow
def test_follow_with_real_visual_localization(scene, tmp_path):
    cfg = SimConfig()
    world = SimWorld(scene, cfg, scene.start, seed=4)
    intr = world.intrinsics
    planner, cam_z = _planner(scene, cfg)
    # Map: reference photos on circles at free spots, keypoints back-projected with true depth.
    lcfg = LocalizeConfig()
    xyz, desc = [], []
    rng = np.random.default_rng(0)
    spots = []
    while len(spots) < 4:
        lo, hi = scene.bounds
        xy = rng.uniform(lo[:2] + 0.5, hi[:2] - 0.5)
        if world.collision_map.clearance_at(xy) > 0.5:
            spots.append(xy)
    for xy in spots:
        for th in np.arange(0, 2 * math.pi, math.radians(30)):
            R = look_rotation(th)
            c = np.array([xy[0], xy[1], scene.floor_z + cfg.camera.height_m])
            img = world.renderer.render(intr, R, c, rng)
            # the map's SIFT: COLMAP's first octave (-1), as the sfm stage extracts it
            kps, d = extract_sift(load_gray(img), -1, lcfg.sift_max_features,
                                  lcfg.sift_num_threads)  # fmt: skip
            depth = world.renderer.depth(intr, R, c)
            ij = np.clip(kps.astype(int), 0, [intr.width - 1, intr.height - 1])
            z = depth[ij[:, 1], ij[:, 0]]
            ok = np.isfinite(z)
            ray = np.c_[(kps[ok] - [intr.cx, intr.cy]) / [intr.fx, intr.fy], np.ones(ok.sum())]
            X = (ray * z[ok, None]) @ R + c - [0, 0, cam_z]
            xyz.append(X)
            desc.append(d[ok])
    X = np.concatenate(xyz)
    _, ids = np.unique(np.floor(X / 0.01).astype(np.int64), axis=0, return_inverse=True)
    md = MapDescriptors(ids.ravel().astype(np.int64), X, np.concatenate(desc))
    cam = pycolmap.Camera(
        model="PINHOLE",
        width=intr.width,
        height=intr.height,
        params=[intr.fx, intr.fy, intr.cx, intr.cy],
    )
    lmap = LocalizationMap(md, cam, cfg=lcfg)
    errors = []

    def localizer(path):
        est = localize(path, lmap, lcfg)
        if est.ok:
            _, c = world.camera_pose()
            errors.append(np.linalg.norm(est.center[:2] - c[:2]))
        return est

    robot = SimRobot(world)
    follower = PathFollower(
        robot,
        SimCamera(world),
        localizer,
        planner,
        FollowConfig(camera_forward_m=cfg.camera.forward_offset_m),
        tmp_path,
        truth=world.truth_record,
    )
    goals = _free_goals(world, planner, np.array([scene.start.x, scene.start.y]), 2, rng)
    for i, g in enumerate(goals):
        res = follower.go_to(g, goal_index=i)
        p = world.truth_pose
        assert res.reached and math.hypot(p.x - g[0], p.y - g[1]) < 0.10, res.reason
    assert len(errors) > 5 and np.median(errors) < 0.0254
    assert world.max_penetration_m < 0.02
