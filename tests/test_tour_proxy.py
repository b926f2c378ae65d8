"""Tour proxy: splat depth against true depth, hole filling, blob removal, bad clouds."""

from __future__ import annotations

import os

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")

import numpy as np
import pytest

from scenebot.taichi_setup import init_taichi
from scenebot.testing import dense as syn
from scenebot.tour.camera import Camera, TourInputError, look_rotation
from scenebot.tour.config import ProxyConfig
from scenebot.tour.proxy import (
    Splatter,
    build_proxy,
    fill_holes,
    remove_small_blobs,
)


@pytest.fixture(scope="module")
def scene_cloud():
    scene = syn.box_room_scene(seed=1)
    pts = syn.sample_surface(scene.vertices, scene.triangles, 150000, seed=1)
    import open3d as o3d

    ans = scene.raycaster.compute_closest_points(o3d.core.Tensor(pts.astype(np.float32)))
    nrm = ans["primitive_normals"].numpy().astype(np.float64)
    return scene, pts, nrm


def test_splat_depth_matches_true_depth(scene_cloud):
    init_taichi("cpu", -1)
    scene, pts, nrm = scene_cloud
    # this cloud is far sparser on screen than an MVS cloud at photo resolution (the default
    # splat cap suits those), so splats may grow to their full neighbour-distance size here
    cfg = ProxyConfig(max_splat_px=8.0, splat_scale=0.7)
    proxy = build_proxy(pts, nrm, None, cfg)
    cam = Camera.pinhole(160, 120, 62.0)
    sp = Splatter(proxy, cfg)
    for heading in (0.0, 2.0, -2.5):
        R = look_rotation(heading)
        t = -R @ np.array([-0.5, 0.2, 0.0])
        K = np.array([[cam.params[0], 0, 80], [0, cam.params[1], 60], [0, 0, 1.0]])
        _, true_depth, _ = syn.render_view(scene, K, R, t, 160, 120, supersample=1)
        z = sp.depth(cam, R, t)
        hit = true_depth > 0
        assert np.isfinite(z[hit]).mean() > 0.99
        rel = np.abs(z[hit] - true_depth[hit]) / true_depth[hit]
        assert np.median(rel) < 0.01
        assert np.mean(rel < 0.05) > 0.95  # edges may blur, the surfaces must not


def test_fill_holes_recovers_plane():
    H, W = 60, 80
    u, v = np.meshgrid(np.arange(W), np.arange(H))
    inv = 0.4 + 0.002 * u + 0.001 * v  # a plane has linear inverse depth on screen
    z = (1.0 / inv).astype(np.float32)
    rng = np.random.default_rng(0)
    holes = rng.random((H, W)) < 0.4
    holes[20:35, 30:50] = True  # a big hole
    zh = z.copy()
    zh[holes] = np.inf
    filled = fill_holes(zh, levels=6)
    assert np.isfinite(filled).all()
    np.testing.assert_allclose(filled, z, rtol=1e-3)
    # nothing is filled without levels
    assert np.isinf(fill_holes(zh, levels=0)[holes]).all()


def test_fill_holes_prefers_background_at_depth_edges():
    z = np.full((10, 30), np.inf, np.float32)
    z[:, :5] = 1.0  # near object on the left
    z[:, 20:] = 4.0  # wall on the right
    filled = fill_holes(z, levels=4)
    assert np.allclose(filled[:, 5:20], 4.0)


def test_remove_small_blobs():
    z = np.full((50, 50), np.inf, np.float32)
    z[10:40, 10:40] = 2.0
    z[2:4, 45:47] = 0.3  # a floater
    out = remove_small_blobs(z, 10)
    assert np.isinf(out[2:4, 45:47]).all()
    assert np.isfinite(out[10:40, 10:40]).all()


@pytest.mark.parametrize("n", [0, 5])
def test_empty_or_tiny_cloud_is_a_clear_error(n):
    pts = np.random.default_rng(0).random((n, 3))
    with pytest.raises(TourInputError, match=r"tour\.proxy\.min_points"):
        build_proxy(pts, None, None, ProxyConfig(), source="fused.ply")


def test_floaters_are_dropped():
    rng = np.random.default_rng(0)
    g = np.stack(np.meshgrid(np.linspace(0, 1, 100), np.linspace(0, 1, 100)), -1).reshape(-1, 2)
    wall = np.concatenate([g, np.zeros((len(g), 1))], 1)
    floaters = rng.random((20, 3)) + np.array([0, 0, 0.5])
    proxy = build_proxy(np.concatenate([wall, floaters]), None, None, ProxyConfig())
    assert len(proxy) == len(wall)
    assert np.all(np.abs(proxy.points[:, 2]) < 1e-6)
    # normals of a plane from PCA
    assert np.all(np.abs(np.abs(proxy.normals[:, 2]) - 1) < 1e-3)


def test_camera_projection_roundtrip():
    cam = Camera(640, 480, (550.0, 552.0, 321.0, 239.0, -0.02, 0.003, 0.001, -0.0005))
    rays = cam.pixel_rays()
    uv = cam.project(rays.reshape(-1, 3) * 2.5)
    u, v = np.meshgrid(np.arange(640) + 0.5, np.arange(480) + 0.5)
    np.testing.assert_allclose(uv, np.stack([u, v], -1).reshape(-1, 2), atol=1e-3)


def test_remove_occluded_keeps_edges_and_drops_see_through():
    from scenebot.tour.proxy import remove_occluded

    z = np.full((20, 40), 1.0, np.float32)
    z[:, 20:] = 3.0  # a true depth edge: the far half stays
    z[8, 10] = 3.0  # the far wall seen through a gap in the near surface
    out = remove_occluded(z, 7, 0.15)
    assert np.isinf(out[8, 10])
    assert np.isfinite(out[:, 20:]).all() and np.isfinite(out[:, :20][np.arange(20) != 8]).all()


def test_one_neighbour_query_sizes_splats_as_a_ball_query_and_a_second_tree():
    """The outlier test and the splat sizes from one k-nearest query equal the direct way: a
    ball count for the outliers, then the spacing from a tree of the points kept (a cloud
    with clustered floaters, some of them next to the surface, so that kept points lose
    neighbours to the outlier test)."""
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(3)
    g = np.stack(np.meshgrid(np.linspace(0, 1, 120), np.linspace(0, 1, 120)), -1).reshape(-1, 2)
    wall = np.concatenate([g + rng.normal(0, 0.001, g.shape), np.zeros((len(g), 1))], 1)
    blobs = rng.random((40, 3)) * [1, 1, 0.05] + [0, 0, 0.004]  # floaters at the wall
    blobs = np.repeat(blobs, 6, axis=0) + rng.normal(0, 0.004, (240, 3))
    pts = np.concatenate([wall, blobs, rng.random((30, 3)) + np.array([0, 0, 0.5])])
    cfg = ProxyConfig()
    proxy = build_proxy(pts, None, None, cfg)

    tree = cKDTree(pts)
    k = cfg.spacing_knn
    radius = cfg.outlier_radius * float(np.median(tree.query(pts, k=k + 1)[0][:, k]))
    count = tree.query_ball_point(pts, radius, return_length=True) - 1
    kept = pts[count >= cfg.outlier_min_neighbors]
    assert len(kept) < len(pts) and len(kept) == len(proxy)
    spacing = cKDTree(kept).query(kept, k=k + 1)[0][:, k]
    spacing = np.minimum(spacing, 4 * np.median(spacing))
    np.testing.assert_array_equal(proxy.points, kept.astype(np.float32))
    np.testing.assert_allclose(proxy.radius, cfg.splat_scale * spacing, rtol=1e-6)


def test_a_moved_proxy_is_the_proxy_of_the_moved_cloud():
    """``transformed`` (the score-validity stage moves the campaign's proxy into a round's
    frame) gives what building the proxy of the moved cloud gives: the outlier test and the
    splat sizes are relative to the cloud's own spacing."""
    rng = np.random.default_rng(5)
    g = np.stack(np.meshgrid(np.linspace(0, 2, 90), np.linspace(0, 1, 60)), -1).reshape(-1, 2)
    cloud = np.concatenate([g, rng.normal(0, 0.002, (len(g), 1))], 1)
    cloud = np.concatenate([cloud, rng.random((25, 3)) + np.array([0, 0, 0.4])])  # floaters
    nrm = np.tile([0.0, 0.0, 1.0], (len(cloud), 1))
    col = rng.integers(0, 255, (len(cloud), 3)).astype(np.uint8)
    c, si = np.cos(0.6), np.sin(0.6)
    R = np.array([[c, -si, 0], [si, c, 0], [0, 0, 1]]) @ np.array(
        [[1, 0, 0], [0, 0, -1], [0, 1, 0]]
    )
    s, t = 1.7, np.array([3.0, -1.0, 2.0])
    cfg = ProxyConfig()
    moved = build_proxy(cloud, nrm, col, cfg).transformed(s, R, t)
    direct = build_proxy(s * cloud @ R.T + t, nrm @ R.T, col, cfg)
    assert len(moved) == len(direct) == len(g)
    np.testing.assert_allclose(moved.points, direct.points, atol=1e-5)
    np.testing.assert_allclose(moved.radius, direct.radius, rtol=1e-4)
    np.testing.assert_allclose(moved.normals, direct.normals, atol=1e-6)
    np.testing.assert_array_equal(moved.colors, direct.colors)


def test_a_saved_proxy_loads_as_built_and_names_what_is_wrong(tmp_path, caplog):
    """The proxy rule's file (``final/tour/proxy.npz``): the tour and the score validity
    load the same arrays the build gave; a proxy built with other settings is used with a
    warning that names them; a file that is no proxy, or none, is an error naming it."""
    from scenebot.tour.proxy import load_proxy, read_proxy, save_proxy

    rng = np.random.default_rng(2)
    g = np.stack(np.meshgrid(np.linspace(0, 1, 60), np.linspace(0, 1, 50)), -1).reshape(-1, 2)
    cloud = np.concatenate([g, rng.normal(0, 0.002, (len(g), 1))], 1)
    col = rng.integers(0, 255, (len(cloud), 3)).astype(np.uint8)
    cfg = ProxyConfig(min_points=100)
    built = build_proxy(cloud, None, col, cfg)
    path = save_proxy(built, tmp_path / "tour" / "proxy.npz", cfg, source="fused.ply")
    assert not list(path.parent.glob("*.part"))  # written under its name only when whole
    loaded = load_proxy(path, cfg)
    for name in ("points", "normals", "colors", "radius"):
        np.testing.assert_array_equal(getattr(loaded, name), getattr(built, name))
        assert getattr(loaded, name).dtype == getattr(built, name).dtype
    assert not caplog.records
    read_proxy(path, ProxyConfig(min_points=100, splat_scale=2.0))
    assert "splat_scale" in caplog.text and str(path) in caplog.text
    np.savez(tmp_path / "other.npz", points=cloud)
    with pytest.raises(TourInputError, match=r"other\.npz: not a proxy"):
        load_proxy(tmp_path / "other.npz", cfg)
    with pytest.raises(TourInputError, match=r"gone\.npz: no prepared proxy.*proxy rule"):
        load_proxy(tmp_path / "gone.npz", cfg)
