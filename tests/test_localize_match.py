"""FLANN index (cached), the ratio test across distinct 3D points, one-to-one matches."""

from __future__ import annotations

import numpy as np
import pytest

from scenebot.localize.config import LocalizeConfig
from scenebot.localize.index import DescriptorIndex, MapDescriptors
from scenebot.localize.match import match_to_map, ratio_test_distinct_points

LOC = LocalizeConfig()


def _sift_like(rng, n):
    d = rng.gamma(0.6, 1.0, (n, 128))
    d = np.sqrt(d / d.sum(axis=1, keepdims=True))  # L1-root like COLMAP
    return np.clip(np.round(d * 512), 0, 255).astype(np.uint8)


def _map(rng, n_points=2000, views=3, noise=3.0):
    base = _sift_like(rng, n_points)
    rows = np.repeat(np.arange(n_points), views)
    desc = np.clip(base[rows] + rng.normal(0, noise, (len(rows), 128)), 0, 255).astype(np.uint8)
    xyz = rng.normal(size=(n_points, 3))[rows]
    return MapDescriptors(rows.astype(np.int64) * 7 + 3, xyz, desc), base


def test_ratio_test_compares_against_a_different_point():
    # neighbours: two rows of point 5 (close), then point 9 (far) -> accepted
    idx = np.array([[0, 1, 2], [0, 2, 1], [0, 1, 3]])
    dist = np.array([[10.0, 11.0, 40.0], [10.0, 11.0, 12.0], [10.0, 11.0, 11.5]])
    pids = np.array([5, 5, 9, 5])
    keep, r = ratio_test_distinct_points(idx, dist, pids, 0.8)
    # row 0: nearest other point at 40 -> ratio 0.25; a plain ratio test (10/11) would reject
    assert keep[0] and r[0] == pytest.approx(0.25)
    # row 1: the second neighbour is another point at 11 -> ambiguous, rejected
    assert not keep[1] and r[1] == pytest.approx(10 / 11)
    # row 2: all neighbours are point 5: the k-th distance bounds the other point's distance
    assert not keep[2] and r[2] == pytest.approx(10 / 11.5)


def test_matching_recovers_true_points_one_to_one():
    rng = np.random.default_rng(0)
    desc, base = _map(rng)
    index = DescriptorIndex(desc.descriptors, trees=4, checks=64)
    true_pt = rng.choice(len(base), 500, replace=False)
    q = np.clip(base[true_pt] + rng.normal(0, 3.0, (500, 128)), 0, 255).astype(np.uint8)
    q = np.vstack([q, _sift_like(rng, 300)])  # 300 queries with no counterpart
    m = match_to_map(q, index, desc, knn=LOC.knn, ratio=LOC.ratio)
    assert len(np.unique(m.point_ids)) == len(m)  # one-to-one
    real = m.query_idx < 500
    correct = m.point_ids[real] == true_pt[m.query_idx[real]] * 7 + 3
    assert correct.mean() > 0.99
    assert real.sum() > 0.9 * 500
    # a plain ratio test between the two nearest descriptors loses most of them
    _, d = index.knn(q[:500], 2)
    assert (d[:, 0] < 0.8 * d[:, 1]).mean() < 0.5
    assert (~real).sum() < 0.05 * 300
    np.testing.assert_allclose(m.xyz, desc.xyz[np.searchsorted(desc.point_ids, m.point_ids)])


def test_index_cache_is_reused_and_invalidated(tmp_path):
    rng = np.random.default_rng(1)
    desc, _ = _map(rng, n_points=500)
    cache = tmp_path / "point_descriptors.flann"
    a = DescriptorIndex.cached(desc, cache)
    assert cache.exists()
    stamp = cache.stat().st_mtime_ns
    b = DescriptorIndex.cached(desc, cache)
    assert cache.stat().st_mtime_ns == stamp  # loaded, not rebuilt
    q = desc.descriptors[:50]
    np.testing.assert_array_equal(a.knn(q, 3)[0], b.knn(q, 3)[0])
    other, _ = _map(np.random.default_rng(2), n_points=500)
    c = DescriptorIndex.cached(other, cache)  # different map: rebuilt
    assert c.knn(other.descriptors[:5], 1)[1].max() == 0.0


def test_map_descriptor_file_validation(tmp_path):
    with pytest.raises(FileNotFoundError, match="sfm stage"):
        MapDescriptors.load(tmp_path / "none.npz")
    bad = tmp_path / "bad.npz"
    np.savez(bad, point_ids=np.arange(3), xyz=np.zeros((3, 3)), descriptors=np.zeros((3, 128)))
    with pytest.raises(ValueError, match="uint8"):
        MapDescriptors.load(bad)
    with pytest.raises(ValueError, match="expected"):
        MapDescriptors(np.arange(3), np.zeros((2, 3)), np.zeros((3, 128), np.uint8))
