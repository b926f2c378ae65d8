"""Plane completion of depth maps: plane detection, hole filling bounded by the plane's own
measured neighbours, nothing filled across a nearer object, depth behind a plane culled."""

from __future__ import annotations

import numpy as np
import pytest

from scenebot.dense.planefill import backproject, detect_planes, fill_view

W, H, F = 160, 120, 100.0
K = np.array([[F, 0, W / 2], [0, F, H / 2], [0, 0, 1.0]])
R, T = np.eye(3), np.zeros(3)  # camera at the origin looking along +z
NORMAL = np.zeros((H, W, 3), np.float32)


def wall(depth=3.0) -> np.ndarray:
    return np.full((H, W), depth, np.float32)


def planes_of(*maps):
    pts = np.concatenate([backproject(d, K, R, T)[d > 0] for d in maps])
    return detect_planes(pts, distance_m=0.01, min_share=0.05, cell_m=0.1)


def test_two_noisy_planes_are_found_once_each():
    rng = np.random.default_rng(0)
    floor = np.c_[rng.uniform(-2, 2, (4000, 2)), rng.normal(-0.35, 0.006, 4000)]
    wallp = np.c_[np.full(3000, 3.0) + rng.normal(0, 0.006, 3000), rng.uniform(-2, 2, (3000, 2))]
    planes = detect_planes(np.r_[floor, wallp], distance_m=0.01, min_share=0.05)
    assert len(planes) == 2  # the noisy floor is not peeled into slices
    fl, wl = planes
    assert abs(fl.normal[2]) > np.cos(np.radians(1)) and abs(wl.normal[0]) > np.cos(np.radians(1))
    assert abs(abs(fl.offset) - 0.35) < 0.005 and abs(abs(wl.offset) - 3.0) < 0.005
    assert fl.area_m2 == pytest.approx(16.0, rel=0.15)
    assert (
        fl.inside(np.array([[0.0, 0.0, -0.35]]))[0] and not fl.inside(np.array([[5, 5, -0.35]]))[0]
    )


def test_a_plain_patch_of_a_wall_is_filled_with_the_wall():
    d = wall()
    d[50:60, 70:80] = 0  # plain paint: no depth over 30 x 30 cm
    planes = planes_of(d)
    fd, fn, filled, culled = fill_view(d, NORMAL, K, R, T, planes, (0.5, 10.0))
    assert filled == 100 and culled == 0
    assert np.allclose(fd[50:60, 70:80], 3.0, atol=1e-3)
    # normals face the camera (negative z in the camera frame)
    assert np.allclose(fn[55, 75], (0, 0, -1), atol=1e-3)


def test_fill_stays_within_the_planes_extent():
    """A 1.8 x 1.2 m plain region is beyond the extent's closing: only its rim (the
    extent's margin and closing) is filled, the middle stays empty."""
    d = wall()
    d[40:80, 50:110] = 0
    planes = planes_of(d)
    fd, _, filled, _ = fill_view(d, NORMAL, K, R, T, planes, (0.5, 10.0))
    assert 0 < filled < 40 * 60
    assert np.all(fd[55:65, 70:90] == 0)
    assert np.allclose(fd[fd > 0], 3.0, atol=1e-3)


def test_a_plain_face_before_the_wall_is_not_filled_with_the_wall():
    rng = np.random.default_rng(1)
    d = wall()
    d[30:90, 40:120] = rng.uniform(1.8, 2.2, (60, 80))  # a box's edges, off every plane
    d[34:86, 44:116] = 0  # its plain face
    planes = planes_of(d)
    fd, _, _, _ = fill_view(d, NORMAL, K, R, T, planes, (0.5, 10.0))
    assert np.all(fd[40:80, 50:110] == 0)  # its middle stays empty


def test_depth_behind_a_plane_is_culled_and_replaced():
    d = wall()
    d[60:63, 80:83] = 5.0  # a match through the wall
    planes = planes_of(d)
    fd, _, filled, culled = fill_view(d, NORMAL, K, R, T, planes, (0.5, 10.0))
    assert culled == 9 and filled == 9
    assert np.allclose(fd[60:63, 80:83], 3.0, atol=1e-3)
    keep, _, _, culled = fill_view(d, NORMAL, K, R, T, planes, (0.5, 10.0), cull_behind=False)
    assert culled == 0 and np.all(keep[60:63, 80:83] == 5.0)
