"""DLT, RQ decomposition, refinement and RANSAC (the paper's pose method)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from scenebot.localize.config import LocalizeConfig
from scenebot.localize.dlt import (
    decompose_camera_matrix,
    dlt,
    dlt_batch,
    position_std_m,
    project,
    ransac_dlt_pose,
    refine_f_r_t,
)
from tests.fixtures.localize import camera_rotation


def _scene(rng, n=300, f=520.0, heading=0.4, centre=(1.0, 2.0, 0.0)):
    R = camera_rotation(heading)
    C = np.array(centre)
    t = -R @ C
    # points 1.5..6 m in front, spread over the view
    cam = np.c_[rng.uniform(-0.6, 0.6, (n, 2)), np.ones(n)] * rng.uniform(1.5, 6.0, (n, 1))
    X = (cam - t) @ R  # world = R^T (cam - t)
    K = np.array([[f, 0, 320.0], [0, f, 240.0], [0, 0, 1.0]])
    x, z = project(K @ np.c_[R, t], X)
    assert np.all(z > 0)
    return K, R, t, X, x


def _ransac(**override) -> dict:
    """ransac_dlt_pose's settings at their LocalizeConfig defaults, ``override`` replacing some."""
    cfg = LocalizeConfig()
    settings = {
        "max_error_px": cfg.ransac_max_error_px,
        "confidence": cfg.ransac_confidence,
        "max_iterations": cfg.ransac_max_iterations,
        "seed": cfg.seed,
    }
    return settings | override


def _rot_err_deg(Ra, Rb):
    return math.degrees(math.acos(np.clip((np.trace(Ra.T @ Rb) - 1) / 2, -1, 1)))


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31 - 1), st.floats(-math.pi, math.pi), st.floats(300, 900))
def test_dlt_and_rq_recover_exact_camera(seed, heading, f):
    rng = np.random.default_rng(seed)
    K, R, t, X, x = _scene(rng, n=20, f=f, heading=heading)
    P = dlt(x, X)
    K2, R2, t2 = decompose_camera_matrix(P)
    np.testing.assert_allclose(K2, K, atol=1e-5 * f)
    np.testing.assert_allclose(R2, R, atol=1e-8)
    np.testing.assert_allclose(t2, t, atol=1e-6)
    assert np.linalg.det(R2) == pytest.approx(1.0)
    _, z = project(P, X)
    assert np.all(z > 0)  # sign convention: points in front have positive depth


def test_decomposition_of_negated_matrix_is_the_same_camera():
    K, R, t, _, _ = _scene(np.random.default_rng(3), n=12)
    P = K @ np.c_[R, t]
    K2, R2, t2 = decompose_camera_matrix(-3.0 * P)
    np.testing.assert_allclose(K2, K, atol=1e-9)
    np.testing.assert_allclose(R2, R, atol=1e-12)
    np.testing.assert_allclose(t2, t, atol=1e-12)


def test_dlt_batch_matches_single():
    rng = np.random.default_rng(4)
    _, _, _, X, x = _scene(rng, n=60)
    idx = rng.integers(0, 60, (5, 8))
    batch = dlt_batch(x[idx], X[idx])
    for b in range(5):
        single = dlt(x[idx[b]], X[idx[b]])
        s = np.sum(single * batch[b]) / np.sum(batch[b] ** 2)
        np.testing.assert_allclose(single, s * batch[b], atol=1e-9)


def test_refinement_recovers_focal_and_pose_from_perturbed_start():
    rng = np.random.default_rng(5)
    _, R, t, X, x = _scene(rng, n=200, f=500.0)
    x = x + rng.normal(0, 0.3, x.shape)
    f1, R1, t1 = refine_f_r_t(x, X, 550.0, camera_rotation(0.45), t + 0.05, 320.0, 240.0)
    assert f1 == pytest.approx(500.0, rel=0.01)
    assert _rot_err_deg(R1, R) < 0.05
    assert np.linalg.norm(-R1.T @ t1 - (-R.T @ t)) < 0.005


@pytest.mark.parametrize("refine_focal", [True, False])
def test_ransac_with_outliers(refine_focal):
    rng = np.random.default_rng(6)
    _, R, t, X, x = _scene(rng, n=400)
    x = x + rng.normal(0, 0.7, x.shape)
    out = rng.random(400) < 0.45
    x[out] = rng.uniform([0, 0], [640, 480], (out.sum(), 2))
    pose = ransac_dlt_pose(
        x, X, 320.0, 240.0, f_init=520.0, refine_focal=refine_focal, **_ransac(seed=1)
    )
    assert pose is not None
    C = -R.T @ t
    assert np.linalg.norm(-pose.R.T @ pose.t - C) < 0.01  # 1 cm at 1.5-6 m depth
    assert _rot_err_deg(pose.R, R) < 0.1
    # almost all true inliers found, and few outliers accepted
    assert pose.inliers[~out].mean() > 0.95
    assert pose.inliers[out].mean() < 0.02
    assert pose.rmse_px < 2.0
    if not refine_focal:
        assert pose.focal_px == 520.0


def test_ransac_too_few_matches_and_pure_noise():
    rng = np.random.default_rng(7)
    X = rng.normal(size=(5, 3)) + np.array([0.0, 0.0, 5.0])
    assert ransac_dlt_pose(rng.uniform(0, 600, (5, 2)), X, 320, 240, **_ransac()) is None
    X = rng.normal(size=(200, 3)) * np.array([2.0, 2.0, 1.0]) + np.array([0.0, 0.0, 5.0])
    x = rng.uniform(0, 640, (200, 2))
    pose = ransac_dlt_pose(
        x, X, 320, 240, f_init=520.0, **_ransac(max_error_px=1.0, max_iterations=300)
    )
    assert pose is None or pose.inliers.sum() < 20  # nothing consistent in random data


def test_matches_on_one_plane_fall_back_to_the_plane_homography():
    rng = np.random.default_rng(8)
    R = camera_rotation(-1.2)
    C = np.array([3.0, 2.0, 0.0])
    t = -R @ C
    # every point on the wall y = 0, seen from 2 m
    n = 300
    X = np.c_[rng.uniform(1.0, 5.0, n), np.zeros(n), rng.uniform(-0.3, 1.5, n)]
    K = np.array([[520.0, 0, 320.0], [0, 520.0, 240.0], [0, 0, 1.0]])
    x, z = project(K @ np.c_[R, t], X)
    keep = (z > 0) & (x[:, 0] > 0) & (x[:, 0] < 640) & (x[:, 1] > 0) & (x[:, 1] < 480)
    X, x = X[keep], x[keep] + rng.normal(0, 0.5, (keep.sum(), 2))
    out = rng.random(len(x)) < 0.3
    x[out] = rng.uniform([0, 0], [640, 480], (out.sum(), 2))
    pose = ransac_dlt_pose(x, X, 320.0, 240.0, f_init=520.0, **_ransac())
    assert pose is not None and pose.planar
    assert np.linalg.norm(-pose.R.T @ pose.t - C) < 0.01
    assert _rot_err_deg(pose.R, R) < 0.2
    assert pose.inliers[~out].mean() > 0.95
    # without a known focal length a planar scene has no DLT solution
    assert ransac_dlt_pose(x, X, 320.0, 240.0, f_init=None, **_ransac(max_iterations=200)) is None


def test_predicted_position_error_matches_the_spread_of_noisy_refits():
    """position_std_m: first-order error of the centre; it matches the spread of poses
    refined from many noisy copies of the matches, grows with the image noise, and is large
    when the matches are few and bunched far away (a poorly determined fix)."""
    rng = np.random.default_rng(4)
    K, R, t, X, x = _scene(rng, n=60)
    f, cx, cy = K[0, 0], K[0, 2], K[1, 2]
    std = position_std_m(x, X, f, cx, cy, R, t, 1.0)
    assert std == pytest.approx(2 * position_std_m(x, X, f, cx, cy, R, t, 0.5), rel=1e-3)
    centres = []
    for _ in range(60):
        xn = x + rng.normal(0, 1.0, x.shape)
        _, Rr, tr = refine_f_r_t(xn, X, f, R, t, cx, cy, refine_focal=False)
        centres.append((-Rr.T @ tr)[:2])
    spread = np.sqrt(np.linalg.eigvalsh(np.cov(np.array(centres).T))[-1])
    assert spread == pytest.approx(std, rel=0.35)
    # 8 matches on a small patch 6 m ahead: the same noise leaves the centre far less certain
    cam = np.c_[rng.uniform(-0.05, 0.05, (8, 2)), np.ones(8)] * 6.0
    Xf = (cam - t) @ R
    xf, _ = project(K @ np.c_[R, t], Xf)
    assert position_std_m(xf, Xf, f, cx, cy, R, t, 1.0) > 20 * std
