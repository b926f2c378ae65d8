"""Map points a candidate view could match: in view, seen from a similar direction and
distance as the map saw them (score.matchable)."""

import numpy as np

from scenebot.geometry import Intrinsics
from scenebot.score.config import ScoreConfig
from scenebot.score.geometry import candidate_views
from scenebot.score.matchable import matchable_points

K = Intrinsics.from_hfov(80, 60, 60.0)


def wall(n=400, x=3.0, seed=0):
    """Points on a wall at x = 3 m, seen by the map from the origin (direction -x, 3 m)."""
    rng = np.random.default_rng(seed)
    xyz = np.column_stack([np.full(n, x), rng.uniform(-3, 3, n), rng.uniform(-0.5, 0.5, n)])
    to_cam = -xyz
    dist = np.linalg.norm(to_cam, axis=1)
    return xyz, to_cam / dist[:, None], dist


def count(poses, xyz, vdir, vdist, **kw):
    """Matchable points per pose, with the score settings not given in ``kw``."""
    cfg = ScoreConfig()
    kw = {"max_angle_deg": cfg.match_angle_deg, "max_scale_ratio": cfg.match_scale_ratio,
          "near_m": cfg.near_m, **kw}  # fmt: skip
    return matchable_points(candidate_views(np.array(poses), K), K.width, K.height, xyz, vdir,
                            vdist, **kw)  # fmt: skip


def test_a_view_like_the_maps_sees_every_point_in_its_image():
    xyz, vdir, vdist = wall()
    views = candidate_views(np.array([[0.0, 0.0, 0.0]]), K)
    X = xyz @ views[0, :9].reshape(3, 3).T + views[0, 9:12]
    u = K.fx * X[:, 0] / X[:, 2] + K.cx
    r = K.fy * X[:, 1] / X[:, 2] + K.cy
    in_image = ((u >= 0) & (u < K.width) & (r >= 0) & (r < K.height)).sum()
    assert 0 < in_image < len(xyz)  # part of the wall lies outside the image
    assert count([[0.0, 0.0, 0.0]], xyz, vdir, vdist)[0] == in_image


def test_looking_away_sees_nothing():
    xyz, vdir, vdist = wall()
    assert count([[0.0, 0.0, np.pi]], xyz, vdir, vdist)[0] == 0


def test_a_grazing_view_of_the_same_wall_matches_nothing():
    """From beside the wall, looking along it: the points are in view but seen at ~80
    degrees from how the map saw them (SIFT does not match across that)."""
    xyz, vdir, vdist = wall()
    pose = [[2.7, -3.5, np.pi / 2]]  # 30 cm from the wall, beyond its end, looking along +y
    in_view = count(pose, xyz, vdir, vdist, max_angle_deg=180, max_scale_ratio=1e9)[0]
    assert in_view > 200
    # only the points at the near end are seen within 45 degrees of the map's direction
    assert count(pose, xyz, vdir, vdist, max_scale_ratio=1e9)[0] < 0.1 * in_view


def test_scale_limit():
    """Points seen from 3 m by the map: from 1 m (ratio 3) they do not match at ratio 2, they
    do at ratio 4; the angle test alone passes."""
    xyz, vdir, vdist = wall()
    pose = [[2.0, 0.0, 0.0]]
    near2 = count(pose, xyz, vdir, vdist, max_scale_ratio=2.0)[0]
    near4 = count(pose, xyz, vdir, vdist, max_scale_ratio=4.0)[0]
    assert near2 < 0.05 * near4 and near4 > 20


def test_no_points_no_matches():
    z = np.zeros((0, 3))
    assert count([[0.0, 0.0, 0.0], [1.0, 0.0, 1.0]], z, z, np.zeros(0)).tolist() == [0, 0]
