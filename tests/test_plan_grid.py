"""Navigation grid: geometry, counts s(c), the KDE of eq. 1, lethal cells, save/load."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from scenebot.plan import PlanConfig, build_navgrid
from scenebot.plan.navgrid import GridGeometry, NavGrid, gaussian_kernel_1d, kde_cost


def test_geometry_centred_on_box_with_n_cells_along_larger_side():
    g = GridGeometry.around(np.array([1.0, -2.0]), np.array([7.0, 1.0]), 100)
    assert g.shape == (50, 100)
    assert g.cell_m == pytest.approx(0.06)
    centre = np.array(g.origin_xy) + 0.5 * g.cell_m * np.array([g.shape[1], g.shape[0]])
    np.testing.assert_allclose(centre, [4.0, -0.5], atol=1e-12)
    # cell_of and centre_of are inverse on cell centres
    cells = np.array([[0, 0], [49, 99], [10, 20]])
    np.testing.assert_array_equal(g.cell_of(g.centre_of(cells)), cells)


def test_counts_only_points_above_threshold_and_inside():
    cfg = PlanConfig(n_cells=10, margin_m=0.0, obstacle_z_min_m=0.0, inflate_m=0.0)
    cams = np.array([[0.0, 0.0], [1.0, 1.0]])
    pts = np.array(
        [
            [0.05, 0.05, 0.5],  # counted
            [0.05, 0.05, 0.1],  # counted, same cell
            [0.05, 0.05, -0.1],  # below the camera plane: floor, not an obstacle
            [0.95, 0.55, 0.2],  # counted
            [5.0, 5.0, 1.0],  # outside the grid
        ]
    )
    g = build_navgrid(pts, cams, cfg)
    assert g.counts.sum() == 3
    assert g.counts[0, 0] == 2
    assert g.counts[5, 9] == 1
    capped = build_navgrid(pts, cams, cfg.model_copy(update={"obstacle_z_max_m": 0.3}))
    assert capped.counts.sum() == 2


def test_kde_is_eq1_separable_gaussian():
    rng = np.random.default_rng(0)
    s = rng.poisson(0.3, (40, 60)).astype(float)
    sigma, trunc = 2.0, 3.0
    k = kde_cost(s, sigma, trunc)
    # Direct 2D evaluation of eq. 1: K(c) = 1/|N| sum w(c, ci) s(ci), Gaussian w.
    w1 = gaussian_kernel_1d(sigma, trunc)
    r = len(w1) // 2
    yy, xx = np.mgrid[-r : r + 1, -r : r + 1]
    w2 = np.exp(-(xx**2 + yy**2) / (2 * sigma**2))
    direct = ndimage.correlate(s, w2, mode="constant", cval=0.0) / w2.size
    np.testing.assert_allclose(k, direct, rtol=1e-5, atol=1e-7)
    assert k.min() >= 0.0


def test_single_point_lethal_threshold_and_inflation():
    cfg = PlanConfig(n_cells=50, margin_m=0.0, kde_sigma_m=0.04, lethal_points=0.9, inflate_m=0.0)
    cams = np.array([[0.0, 0.0], [1.0, 1.0]])
    g = build_navgrid(np.array([[0.51, 0.51, 0.3]]), cams, cfg)
    # One point: the score (weighted count) is exactly 1 in its cell, < 1 elsewhere.
    iy, ix = g.geometry.cell_of(np.array([0.51, 0.51]))
    assert g.score[iy, ix] == pytest.approx(1.0, rel=1e-5)
    assert g.lethal.sum() == 1 and g.lethal[iy, ix]
    inflated = build_navgrid(
        np.array([[0.51, 0.51, 0.3]]), cams, cfg.model_copy(update={"inflate_m": 0.1})
    )
    # Every cell centre within 0.1 m (5 cells) of the lethal cell is lethal.
    ys, xs = np.nonzero(inflated.lethal)
    d = np.hypot(ys - iy, xs - ix) * g.geometry.cell_m
    assert d.max() <= 0.1 + 1e-9
    assert inflated.lethal.sum() == np.sum(
        np.hypot(*np.mgrid[-5:6, -5:6]) * g.geometry.cell_m <= 0.1 + 1e-9
    )
    assert np.all(g.cost_per_m >= 1.0)


def test_save_load_roundtrip(tmp_path):
    rng = np.random.default_rng(1)
    pts = np.c_[rng.uniform(0, 4, (500, 2)), rng.uniform(-0.2, 1, 500)]
    g = build_navgrid(pts, np.array([[0.5, 0.5], [3.5, 3.0]]), PlanConfig())
    g.save(tmp_path / "navgrid.npz")
    h = NavGrid.load(tmp_path / "navgrid.npz")
    assert h.geometry == g.geometry
    for name in ("counts", "kde", "score", "lethal", "cost_per_m"):
        np.testing.assert_array_equal(getattr(h, name), getattr(g, name))


def test_no_cameras_is_a_clear_error():
    with pytest.raises(ValueError, match="no camera centres"):
        build_navgrid(np.zeros((3, 3)), np.zeros((0, 2)))
