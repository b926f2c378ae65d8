"""The dense stage's views in worker processes (issue 22): the maps do not depend on the
worker count, and the plane fill's vectorised steps give what their direct forms give."""

from __future__ import annotations

import numpy as np
import pytest

from scenebot.dense import stage
from scenebot.dense import workspace as ws
from scenebot.dense.config import DenseConfig
from scenebot.dense.parallel import ViewPool, worker_count
from scenebot.dense.planes.detect import _first_per_voxel
from scenebot.dense.planes.fill import _plane_hits
from scenebot.dense.planes.geometry import Plane, image_window
from scenebot.dense.planes.labels import DIRECTIONS, _nearest_labels
from scenebot.testing.dense import box_room_scene, make_dataset, stereo_rig

W, H = 160, 120


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    root = tmp_path_factory.mktemp("dense_parallel")
    centers, headings = stereo_rig(num_per_row=3, half_width_m=0.3)
    _rec, views = make_dataset(root, box_room_scene(), centers, headings, W, H, num_points=2000)
    return root, views


def _run(root, out, num_threads):
    cfg = DenseConfig(max_image_size=W, num_threads=num_threads, taichi_arch="cpu", plots=False)
    return stage.run(cfg, stage.DenseInputs(root / "sparse", root / "images"),
                     stage.DenseOutputs(out))  # fmt: skip


def test_two_worker_processes_give_the_maps_of_one(capture, tmp_path):
    root, views = capture
    one = _run(root, tmp_path / "one", 1)
    two = _run(root, tmp_path / "two", 2)
    assert one["processes"] == 1 and two["processes"] == 2
    for v in views:
        for step in ("photometric", "geometric"):  # geometric: filtered and plane-filled
            for a, b in zip(ws.read_maps(tmp_path / "one", v.name, step),
                            ws.read_maps(tmp_path / "two", v.name, step), strict=True):  # fmt: skip
                np.testing.assert_array_equal(a, b)
    for a, b in zip(one["views"], two["views"], strict=True):
        assert a["fraction_with_depth"] == b["fraction_with_depth"] > 0.3
        assert a["fraction_plane_filled"] == b["fraction_plane_filled"]
    assert one["plane_fill"]["planes"] == two["plane_fill"]["planes"]
    assert not (tmp_path / "two" / "stereo" / "filtered").exists()
    assert not list((tmp_path / "two" / "stereo").glob(".shared-*"))


def test_the_pool_keeps_the_order_hands_over_shared_data_and_raises(tmp_path):
    with ViewPool(2, 0, tmp_path) as pool:
        assert pool.map(divmod, list(range(10)), 3) == [divmod(i, 3) for i in range(10)]
        with pytest.raises(ZeroDivisionError):
            pool.map(divmod, [1, 2], 0)
    assert ViewPool(1, 0, tmp_path).map(divmod, [7], 2) == [(3, 1)]
    assert not list(tmp_path.glob(".shared-*"))


def test_worker_count_follows_num_threads_on_the_cpu_only():
    assert worker_count(3, on_cpu=True) == 3
    assert worker_count(-1, on_cpu=True) >= 1
    assert worker_count(4, on_cpu=False) == 1


def _nearest_by_steps(cell_label, measured, max_steps):
    """The nearest measured cell per direction, step by step (the direct form)."""
    h, w = cell_label.shape
    out = np.full((len(DIRECTIONS), h, w), -2, np.int32)
    for k, (dr, dc) in enumerate(DIRECTIONS):
        for r in range(h):
            for c in range(w):
                for s in range(1, max_steps + 1):
                    rr, cc = r + dr * s, c + dc * s
                    if not (0 <= rr < h and 0 <= cc < w):
                        break
                    if measured[rr, cc]:
                        out[k, r, c] = cell_label[rr, cc]
                        break
    return out


@pytest.mark.parametrize("shape,share,steps", [((9, 13), 0.2, 4), ((14, 6), 0.05, 20)])
def test_nearest_labels_are_those_found_step_by_step(shape, share, steps):
    rng = np.random.default_rng(1)
    measured = rng.random(shape) < share
    label = np.where(measured, rng.integers(-1, 5, shape), -2).astype(np.int32)
    np.testing.assert_array_equal(
        _nearest_labels(label, measured, steps), _nearest_by_steps(label, measured, steps)
    )


def test_first_point_per_voxel_is_numpys_unique_by_rows():
    rng = np.random.default_rng(2)
    keys = rng.integers(-40, 40, (5000, 3))
    np.testing.assert_array_equal(
        _first_per_voxel(keys), np.unique(keys, axis=0, return_index=True)[1]
    )


def _square(normal, offset, basis, half, boundary=True):
    """A plane with a square extent of side 2 * half around its point nearest the origin."""
    normal = np.asarray(normal, float)
    occ = np.ones((int(2 * half / 0.1), int(2 * half / 0.1)), bool)
    occ[3:5, 3:5] = False  # a hole
    return Plane(normal, offset, np.asarray(basis, float), -offset * normal, 0.1,
                 np.array([-half, -half]), occ, 100, boundary)  # fmt: skip


def test_plane_hits_in_the_planes_image_window_are_those_of_every_pixel():
    K = np.array([[90.0, 0, 40], [0, 90.0, 30], [0, 0, 1]])
    R, t = np.eye(3), np.zeros(3)  # looking along +z
    planes = [
        _square([0, 0, -1], 2.0, [[1, 0, 0], [0, 1, 0]], 0.5),  # a patch ahead: a window
        _square([0, -1, 0], 0.4, [[1, 0, 0], [0, 0, 1]], 3.0, boundary=False),  # a floor
        _square([0, 0, 1], 1.0, [[1, 0, 0], [0, 1, 0]], 1.0),  # behind the camera: none
        _square([1, 0, 0], -0.005, [[0, 1, 0], [0, 0, 1]], 1.0),  # through the camera
    ]
    assert image_window(planes[2], K, R, t, (60, 80)) is None
    assert image_window(planes[3], K, R, t, (60, 80)) == (slice(0, 60), slice(0, 80))
    rows, cols = image_window(planes[0], K, R, t, (60, 80))
    assert rows.start > 0 and rows.stop < 60 and cols.start > 0 and cols.stop < 80
    ray, centre, hits, hits_fill = _plane_hits(K, R, t, planes, (60, 80), True, 0.05)
    for j, pl in enumerate(planes):  # the direct form: every pixel, every plane
        with np.errstate(divide="ignore", invalid="ignore"):
            z = -(centre @ pl.normal + pl.offset) / (ray @ pl.normal)
        ok = np.isfinite(z) & (z > 0)
        ok[ok] = pl.inside(centre + z[ok, None] * ray[ok])
        np.testing.assert_array_equal(hits[j], np.where(ok, z, np.inf))
    assert np.isfinite(hits[0]).sum() > 100 and np.isfinite(hits[1]).sum() > 100
    assert not np.isfinite(hits[2]).any()
    assert np.isfinite(hits_fill).sum() >= np.isfinite(hits[:2]).sum() * 0.9


def test_one_blas_thread_meanwhile_then_as_before():
    from scenebot.dense.parallel import _openblas, one_blas_thread

    libs = _openblas()
    before = [get() for get, _ in libs]
    with one_blas_thread():
        assert all(get() == 1 for get, _ in libs)
    assert [get() for get, _ in libs] == before
