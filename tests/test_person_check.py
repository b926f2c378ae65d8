"""The checks of a person's map without the truth (scenebot.sfm.person_check): verified
pairs the map does not hold, and the eye-height plane of the photos taken standing."""

from __future__ import annotations

import math

import numpy as np
import pycolmap
import pytest

from scenebot.sfm.mapping import filter_observations
from scenebot.sfm.person_check import (
    MIN_MEDIAN_PAIR_SHARE,
    PairGeometry,
    blamed_pairs,
    check_person_map,
    contradicted_pairs,
    fit_plane,
    height_plane,
    pair_track_shares,
    turned_in_place,
)
from tests.fixtures.synthetic import synthetic_database


def _walk(n=32, eye=1.5, std=0.05, seed=0) -> tuple[list[str], np.ndarray]:
    """Camera centres (m) of a walk along the walls of a 6 x 5 m room at eye height."""
    rng = np.random.default_rng(seed)
    u = np.arange(n) / n * 4
    side, f = np.floor(u).astype(int), u % 1
    corners = np.array([[0.6, 0.6], [5.4, 0.6], [5.4, 4.4], [0.6, 4.4], [0.6, 0.6]])
    xy = corners[side] + f[:, None] * (corners[side + 1] - corners[side])
    z = eye + rng.normal(0, std, n)
    return [f"round_000/capture/images/r000_{i:04d}.jpg" for i in range(n)], np.c_[xy, z]


def _rot_x(deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def test_the_plane_of_a_right_walk_is_level_and_names_no_photo():
    names, C = _walk()
    off, stats = height_plane(names, C, 0.05)
    assert off == {} and stats["planar"]
    assert stats["tilt_deg"] < 1.0  # 5 cm of height noise over metres
    assert 0.02 < stats["robust_std_m"] < 0.08


def test_the_plane_recovers_a_tilted_frame():
    _, C = _walk(seed=1)
    R = _rot_x(3.0)  # the frame's up 3 degrees off, as the optical axes left it
    n, _ = fit_plane(C @ R.T)
    assert math.degrees(math.acos(abs(n @ (R @ [0, 0, 1])))) < 0.5


def test_photos_registered_off_the_plane_are_named():
    names, C = _walk(seed=2)
    C[20, 2] -= 0.64  # two photos of a white wall registered 0.6 m low (office, seed 2)
    C[21, 2] -= 0.67
    off, stats = height_plane(names, C, 0.05)
    assert set(off) == {names[20], names[21]}
    assert off[names[20]] == pytest.approx(-0.64, abs=0.15)
    assert stats["planar"]  # the others still lie on one plane


def test_a_walk_folded_about_a_horizontal_axis_has_photos_off_the_plane():
    names, C = _walk(seed=3)
    # the second half of the walk folded down by 10 degrees about a line across the room
    hinge = np.array([3.0, 2.5, 1.5])
    C[16:] = (C[16:] - hinge) @ _rot_x(10.0).T + hinge
    off, _ = height_plane(names, C, 0.05)
    assert len(off) >= 3  # those farthest from the hinge, on either side of the fold
    assert height_plane(*_walk(seed=3), 0.05)[0] == {}


def test_a_walk_drifting_in_height_is_not_planar():
    names, C = _walk(seed=4)
    C[:, 2] += 0.7 * np.arange(len(C)) / len(C)  # an open chain climbing 0.7 m (office)
    _, stats = height_plane(names, C, 0.05)
    assert not stats["planar"] and stats["robust_std_m"] > 0.1
    _, right = height_plane(*_walk(seed=4), 0.05)
    assert right["planar"]


def test_contradicted_pairs_are_those_far_below_the_median_pair():
    shares = [("a", "b", 50, 0.8), ("b", "c", 60, 0.7), ("c", "d", 40, 0.75), ("d", "e", 90, 0.1)]
    bad, stats = contradicted_pairs(shares, 0.25)
    assert [p[:2] for p in bad] == [("d", "e")]
    assert stats["median_share"] == pytest.approx(0.725)
    assert contradicted_pairs([], 0.25) == ([], {"checked": 0})


@pytest.fixture
def synthetic(tmp_path):
    """A synthetic model and its database (verified pairs with inlier matches)."""
    return synthetic_database(tmp_path, 8, 300)


def test_a_right_map_holds_every_verified_pair(synthetic):
    rec, db_path = synthetic
    shares = pair_track_shares(rec, db_path)
    assert len(shares) == 28  # 8 photos, every pair verified
    assert min(s for *_, s in shares) == pytest.approx(1.0)
    check = check_person_map(
        rec, db_path, standing=[], to_frame=None, min_pair_share=0.25, height_std_m=0.05
    )
    assert check.ok and check.stats["plane"]["why_not"] == "no metric scale"


def test_a_photo_registered_off_contradicts_its_pairs(synthetic):
    rec, db_path = synthetic
    iid = sorted(rec.reg_image_ids())[3]
    name = rec.image(iid).name
    frame = rec.frame(rec.image(iid).frame_id)
    # turned by 11 degrees: the map's refinement then drops its observations as outliers
    turn = pycolmap.Rigid3d(pycolmap.Rotation3d(np.array([0.0, 0.2, 0.0])), np.zeros(3))
    frame.rig_from_world = turn * frame.rig_from_world
    filter_observations(rec, 4.0)
    check = check_person_map(
        rec, db_path, standing=[], to_frame=None, min_pair_share=0.25, height_std_m=0.05
    )
    assert not check.ok
    assert len(check.contradicted) == 7  # the photo with each of the 7 others
    assert all(name in pair[:2] for pair in check.contradicted)
    assert "not hold" in check.problems[0] and name.rsplit("/", 1)[-1] in check.problems[0]


def test_the_simulated_persons_height_spread_is_the_planes_unless_set():
    from scenebot.config import Config

    sim = Config(robot="person-sim", person_sim={"height_std_m": 0.03})
    assert sim.sfm.person_height_std_m == 0.03
    assert Config(robot="sim").sfm.person_height_std_m == 0.1  # the default: a real person
    mine = Config(robot="person-sim", sfm={"person_height_std_m": 0.2})
    assert mine.sfm.person_height_std_m == 0.2


def test_a_map_holding_few_of_its_median_pairs_matches_fails_as_a_whole(synthetic):
    rec, db_path = synthetic
    for pid in list(rec.point3D_ids()):  # global SfM of turn-in-place circles: no tracks
        rec.delete_point3D(pid)
    check = check_person_map(
        rec, db_path, standing=[], to_frame=None, min_pair_share=0.25, height_std_m=0.05
    )
    assert not check.ok and check.whole  # before: the bar, 0.25 x a median of 0, passed it
    assert check.contradicted == [] and check.named_photos == set()  # no photo to blame
    assert f"below {MIN_MEDIAN_PAIR_SHARE:.0%}" in check.problems[0]
    off = check_person_map(
        rec, db_path, standing=[], to_frame=None, min_pair_share=0.0, height_std_m=0.05
    )
    assert off.ok  # the pair check turned off


def test_pairs_turned_in_place_are_not_checked_but_counted():
    def pair(parallax, turn):
        return PairGeometry("a", "b", 50, parallax, turn, 0.1)

    assert pair(0.5, 20.0).turned_in_place  # a circle's neighbours: 1 deg, turned 20
    assert not pair(3.0, 40.0).turned_in_place  # a walk's corner
    assert not pair(0.5, 2.0).turned_in_place  # the same view twice
    pairs = [pair(0.5, 20.0), PairGeometry("c", "d", 50, 6.0, 20.0, 0.8)]
    assert pair_track_shares(None, None, pairs=pairs) == [("c", "d", 50, 0.8)]
    assert turned_in_place(pairs) == {"a", "b"}


def test_a_map_failing_as_a_whole_ranks_below_one_with_photos_to_leave_out():
    from types import SimpleNamespace

    from scenebot.sfm.person_check import PersonCheck
    from scenebot.sfm.stage import _unplaced

    s = SimpleNamespace(photos=[None] * 45)
    mres = SimpleNamespace(reconstruction=SimpleNamespace(num_reg_images=lambda: 45))
    folded = PersonCheck(False, ["median 0 %"], whole=True)
    named = PersonCheck(False, ["12 pairs"], [(f"p{i}", f"q{i}", 40, 0.0) for i in range(12)])
    assert _unplaced(s, mres, named) < _unplaced(s, mres, folded)
    assert _unplaced(s, mres, PersonCheck(True)) < _unplaced(s, mres, named)


def test_a_pair_contradicted_for_neither_photo_is_a_wrong_match():
    """Photo x has 3 of its 4 pairs contradicted: registered off, its pairs are blamed. The
    pair a-b is contradicted too, but a and b agree with the map on 2 of their 3 pairs each:
    a wrong match (identical objects at two places), not a wrong map."""
    held = [("a", "c", 50, 0.8), ("a", "d", 50, 0.8), ("b", "c", 50, 0.8), ("b", "d", 50, 0.7)]
    held += [("x", "e", 40, 0.7), ("c", "d", 60, 0.9), ("f", "c", 50, 0.8), ("f", "d", 50, 0.8)]
    wrong = ("a", "b", 40, 0.05)
    off = [("x", "c", 40, 0.0), ("x", "d", 40, 0.1), ("f", "x", 40, 0.05)]
    shares = [*held, wrong, *off]
    bad, _ = contradicted_pairs(shares, 0.25)
    assert sorted(bad) == sorted([wrong, *off])
    blamed, wrong_matches = blamed_pairs(bad, shares)
    assert sorted(blamed) == sorted(off) and wrong_matches == [wrong]


def test_only_the_new_photos_of_a_registered_round_are_left_out_without_mapping_again(synthetic):
    """A round whose new photos were registered into the previous map (poses held): when
    the check names only new photos (a pair with an old photo blames the new one), they are
    left out without mapping everything again; a pair of two old photos, a map failing as
    a whole, or a map made from scratch, is mapped again as before."""
    from types import SimpleNamespace

    from scenebot.sfm.person_check import PersonCheck
    from scenebot.sfm.stage import _only_new_photos_named

    rec, _ = synthetic
    names = [rec.image(i).name for i in sorted(rec.reg_image_ids())]
    previous = pycolmap.Reconstruction(rec)
    for iid in sorted(previous.reg_image_ids())[-2:]:
        previous.deregister_frame(previous.image(iid).frame_id)
    old, new = names[:6], names[6:]
    s = SimpleNamespace(previous=previous)
    fast = SimpleNamespace(mode="registered")

    def check(pairs, whole=False):
        return PersonCheck(False, ["x"], [(a, b, 40, 0.0) for a, b in pairs], whole=whole)

    assert _only_new_photos_named(s, fast, check([(old[0], new[0]), (new[0], new[1])]))
    assert _only_new_photos_named(s, SimpleNamespace(mode="registered+global"),
                                  check([(new[1], old[2])]))  # fmt: skip
    assert not _only_new_photos_named(s, fast, check([(old[0], old[1])]))
    assert not _only_new_photos_named(s, fast, check([(old[0], new[0])], whole=True))
    assert not _only_new_photos_named(s, SimpleNamespace(mode="incremental"),
                                      check([(old[0], new[0])]))  # fmt: skip
    assert not _only_new_photos_named(SimpleNamespace(previous=None), fast,
                                      check([(old[0], new[0])]))  # fmt: skip
