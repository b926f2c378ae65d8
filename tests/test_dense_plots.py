"""The dense stage's pictures: the cloud from above (each cell its highest point) and the
z-buffered splats from a camera (the nearest point wins)."""

from __future__ import annotations

import numpy as np

from scenebot.dense.plots import splat, top_view


def test_the_top_view_shows_each_cells_highest_point_and_white_elsewhere():
    rng = np.random.default_rng(0)
    # a floor at z 0 (red) over 2 x 1 m, a box top at z 0.8 (blue) over one quarter of it
    floor = np.column_stack([rng.uniform(0, 2, 20000), rng.uniform(0, 1, 20000), np.zeros(20000)])
    box = np.column_stack([rng.uniform(0, 1, 5000), rng.uniform(0, 0.5, 5000), np.full(5000, 0.8)])
    pts = np.concatenate([box, floor])  # the box first: order must not matter
    cols = np.concatenate(
        [np.tile([0.0, 0.0, 1.0], (5000, 1)), np.tile([1.0, 0.0, 0.0], (20000, 1))]
    )
    img, (x0, x1, y0, y1) = top_view(pts, cols, max_px=40)
    assert img.shape[1:] == (40, 3) and img.shape[0] in (20, 21)  # 2 x 1 m in 5 cm cells
    assert x0 <= pts[:, 0].min() and x1 >= pts[:, 0].max()
    assert y0 <= pts[:, 1].min() and y1 >= pts[:, 1].max()
    # row 0 is the smallest y (origin "lower"): the box covers rows < 10 and columns < 20
    inner_box = img[1:9, 1:19].reshape(-1, 3)
    inner_floor = img[11:19, 21:39].reshape(-1, 3)
    assert np.all(inner_box == [0.0, 0.0, 1.0])
    assert np.all(inner_floor == [1.0, 0.0, 0.0])
    # a sparse cloud leaves cells without a point white
    few, few_cols = pts[::500], cols[::500]
    sparse, _ = top_view(few, few_cols, max_px=40)
    assert (sparse == 1.0).all(axis=2).mean() > 0.5


def test_a_splat_shows_the_nearest_point_over_a_white_background():
    K = np.array([[100.0, 0, 50], [0, 100.0, 40], [0, 0, 1]])
    R, t = np.eye(3), np.zeros(3)
    # two points on the same ray, 1 m (green) and 2 m (red) away, and one far to the side
    pts = np.array([[0.0, 0.0, 2.0], [0.0, 0.0, 1.0], [0.3, 0.0, 1.0]])
    cols = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]])
    for order in ([0, 1, 2], [1, 0, 2]):
        img = splat(pts[order], cols[order], K, R, t, 100, 80, radius=1)
        assert np.allclose(img[40, 50], [0, 1, 0])  # the nearer point on the shared ray
        assert np.allclose(img[40, 80], [0, 0, 1])
        assert np.allclose(img[5, 5], [1, 1, 1])
        assert np.allclose(img[39:42, 49:52].reshape(-1, 3), [0, 1, 0])  # a 3x3 splat
