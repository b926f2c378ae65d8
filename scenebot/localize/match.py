"""2D-3D matching of query descriptors to the map's point descriptors.

The map stores several descriptors per 3D point, so the two nearest descriptors of a query
often belong to the same point, and a plain Lowe ratio test between them would reject good
matches. The test here compares the nearest descriptor with the nearest descriptor of a
*different* 3D point among the ``knn`` neighbours. When all ``knn`` neighbours belong to the
same point, the ``knn``-th distance is a lower bound of the distance to any other point, and
the test uses that bound (it can only reject more, never accept a doubtful match).
Finally each 3D point keeps only its best query (one-to-one matches).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scenebot.localize.index import DescriptorIndex, MapDescriptors


@dataclass(frozen=True)
class Matches:
    """2D-3D correspondences.

    Attributes:
        query_idx: (M,) int64 rows of the query features.
        point_ids: (M,) int64 matched 3D point ids (distinct).
        xyz: (M, 3) float64 matched 3D points (m, map frame).
        distance: (M,) float32 descriptor distance of the match.
        ratio: (M,) float32 distance / distance to the nearest other point.
    """

    query_idx: np.ndarray
    point_ids: np.ndarray
    xyz: np.ndarray
    distance: np.ndarray
    ratio: np.ndarray

    def __len__(self) -> int:
        return len(self.query_idx)


def ratio_test_distinct_points(
    nn_idx: np.ndarray, nn_dist: np.ndarray, point_ids: np.ndarray, ratio: float
) -> tuple[np.ndarray, np.ndarray]:
    """The ratio test against the nearest descriptor of a different 3D point.

    Args:
        nn_idx: (Q, k) map rows of the nearest neighbours, ascending distance.
        nn_dist: (Q, k) their distances.
        point_ids: (N,) 3D point id of every map row.
        ratio: acceptance ratio (< 1).

    Returns:
        keep (Q,) bool, and the ratio (Q,) float32 of each query.
    """
    q, k = nn_idx.shape
    if q == 0:
        return np.zeros(0, bool), np.zeros(0, np.float32)
    pid = point_ids[nn_idx]
    other = pid != pid[:, :1]
    has_other = other.any(axis=1)
    first_other = np.where(has_other, other.argmax(axis=1), k - 1)
    d_other = nn_dist[np.arange(q), first_other]
    d1 = nn_dist[:, 0]
    r = np.where(d_other > 0, d1 / np.maximum(d_other, 1e-12), 1.0).astype(np.float32)
    return r < ratio, r


def match_to_map(
    query_desc: np.ndarray,
    index: DescriptorIndex,
    desc: MapDescriptors,
    knn: int,
    ratio: float,
) -> Matches:
    """Match query descriptors to 3D points (ratio test across distinct points, one-to-one).

    Args:
        query_desc: (Q, 128) uint8 query SIFT descriptors.
        index: the FLANN index over ``desc.descriptors``.
        desc: the map's point descriptors.
        knn: neighbours fetched per query (>= 2; ``localize.knn``).
        ratio: Lowe ratio (``localize.ratio``).
    """
    nn_idx, nn_dist = index.knn(query_desc, knn)
    keep, r = ratio_test_distinct_points(nn_idx, nn_dist, desc.point_ids, ratio)
    qi = np.nonzero(keep)[0]
    rows = nn_idx[qi, 0]
    dist = nn_dist[qi, 0]
    pids = desc.point_ids[rows]
    # One-to-one: for every 3D point keep the query with the smallest distance.
    order = np.lexsort((dist, pids))
    first = np.ones(len(order), bool)
    first[1:] = pids[order][1:] != pids[order][:-1]
    sel = np.sort(order[first])
    return Matches(
        query_idx=qi[sel].astype(np.int64),
        point_ids=pids[sel],
        xyz=desc.xyz[rows[sel]],
        distance=dist[sel].astype(np.float32),
        ratio=r[qi[sel]],
    )
