"""Pairs of photos their cameras' orientation contradicts (scenebot.sfm.orientation), on a
pycolmap synthetic dataset: every pair verified, the true poses known."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pycolmap
import pytest

from scenebot.sfm.orientation import drop_pairs_against_orientation, rotation_from_orientation
from scenebot.sfm.photos import Photo
from tests.fixtures.synthetic import synthetic_database, tracked_photos


def orientation_of(R: np.ndarray) -> tuple[float, float, float]:
    """(heading, pitch, roll) (deg) of a cam_from_world rotation, as a phone reads it."""
    fwd = R[2]
    h, p = math.atan2(fwd[1], fwd[0]), math.asin(float(np.clip(fwd[2], -1, 1)))
    roll = R @ rotation_from_orientation((math.degrees(h), math.degrees(p), 0.0)).T
    return math.degrees(h), math.degrees(p), math.degrees(math.atan2(roll[1, 0], roll[0, 0]))


@pytest.fixture()
def dataset(tmp_path):
    """Ten photos of 400 points, every pair matched and verified."""
    rec, db_path = synthetic_database(tmp_path, 10, 400)
    return db_path, rec


def _verified(db_path: Path) -> int:
    db = pycolmap.Database.open(str(db_path))
    try:
        _, inliers = db.read_two_view_geometry_num_inliers()
        return int(np.sum(np.asarray(inliers) >= 15))
    finally:
        db.close()


def test_pairs_whose_rotation_the_orientation_contradicts_leave_the_map(dataset):
    """Readings 5 deg off keep every pair; two photos whose readings are turned 90 deg (a
    copy of the texture on another wall) lose their pairs with the eight others but one, which
    keeps them joined to the rest, not the one between them (turned alike, they agree); the
    matches stay."""
    db_path, rec = dataset
    rng = np.random.default_rng(0)
    photos, turned = [], set()
    for k, iid in enumerate(sorted(rec.reg_image_ids())):
        im = rec.image(iid)
        h, p, r = orientation_of(im.cam_from_world().rotation.matrix())
        if k in (3, 7):
            h += 90.0
            turned.add(im.name)
        reading = (h + rng.normal(0, 5), p + rng.normal(0, 1), r)
        photos.append(Photo(im.name, Path(im.name), orientation=reading))
    before = _verified(db_path)
    assert before == 45
    stats = drop_pairs_against_orientation(db_path, photos, 35.0, 15)
    assert stats["photos"] == 10 and stats["checked"] == 45 and stats["no_pose"] == 0
    assert stats["dropped"] == 15 and stats["kept_to_connect"] == 1 and _verified(db_path) == 30
    assert stats["disagreement_deg"]["median"] < 15.0
    db = pycolmap.Database.open(str(db_path))
    try:
        assert db.num_matched_image_pairs() == 45  # the matches stay: never matched again
    finally:
        db.close()


def test_no_orientation_or_the_check_off_drops_nothing(dataset):
    db_path, rec = dataset
    names = [rec.image(i).name for i in sorted(rec.reg_image_ids())]
    bare = [Photo(n, Path(n)) for n in names]
    assert drop_pairs_against_orientation(db_path, bare, 35.0, 15)["checked"] == 0
    wrong = [Photo(n, Path(n), orientation=(90.0 * k, 0.0, 0.0)) for k, n in enumerate(names)]
    assert drop_pairs_against_orientation(db_path, wrong, 0.0, 15)["dropped"] == 0
    assert _verified(db_path) == 45
    # readings wrong by multiples of 90 deg: most pairs go, but the photos stay joined
    stats = drop_pairs_against_orientation(db_path, wrong, 35.0, 15)
    assert stats["dropped"] > 20 and stats["kept_to_connect"] >= 1
    assert _verified(db_path) == 45 - stats["dropped"]
    db = pycolmap.Database.open(str(db_path))
    try:
        pair_ids, inliers = db.read_two_view_geometry_num_inliers()
    finally:
        db.close()
    joined = {min(rec.reg_image_ids())}
    pairs = [
        pycolmap.pair_id_to_image_pair(int(p))
        for p, n in zip(pair_ids, inliers, strict=True)
        if n >= 15
    ]
    for _ in range(10):
        joined |= {x for a, b in pairs if {a, b} & joined for x in (a, b)}
    assert joined == set(rec.reg_image_ids())


def test_a_pair_is_dropped_only_where_the_photos_stay_joined():
    """contradicted: the pairs are taken in order of agreement; one beyond the bound that
    joins two parts stays, the others beyond it go."""
    from scenebot.sfm.orientation import contradicted

    judged = [(2.0, 1, 2), (3.0, 2, 3), (80.0, 1, 3), (90.0, 3, 4), (120.0, 4, 1), (5.0, 5, 6)]
    assert contradicted(judged, 35.0) == [(1, 3), (4, 1)]
    assert contradicted(judged, 200.0) == []


def test_pairs_whose_translation_the_tracked_motion_contradicts_leave_the_map(dataset):
    """The true tracked motion keeps every pair; a photo whose tracked centre lies far from
    where it was (a wallpaper matched one motif along: the right rotation, the wrong
    translation) loses its pairs but the one that keeps it joined; the orientation check
    off, the rotation right: only the translation can tell."""
    db_path, rec = dataset
    right = drop_pairs_against_orientation(db_path, tracked_photos(rec), 0.0, 15, 30.0, 0.0)
    m = right["motion"]
    assert m["photos"] == 10 and m["checked"] == 45 and m["dropped"] == 0
    assert m["angle_deg"]["p90"] < 1.0 and _verified(db_path) == 45
    spread = np.ptp([rec.image(i).projection_center() for i in rec.reg_image_ids()], axis=0)
    moved = {4: 3.0 * spread * [1.0, -1.0, 0.0]}
    wrong_track = tracked_photos(rec, moved=moved)
    wrong = drop_pairs_against_orientation(db_path, wrong_track, 0.0, 15, 30.0, 0.0)
    assert wrong["motion"]["dropped"] >= 6 and wrong["dropped"] == 0
    assert _verified(db_path) == 45 - wrong["motion"]["dropped"]
    db = pycolmap.Database.open(str(db_path))
    try:
        ids = sorted(rec.reg_image_ids())
        pair_ids, _ = db.read_two_view_geometry_num_inliers()
        left = {pycolmap.pair_id_to_image_pair(int(p)) for p in pair_ids}
    finally:
        db.close()
    lost = {(a, b) for a, b in itertools.combinations(ids, 2)} - left
    assert all(ids[4] in pair for pair in lost)  # only the wrongly tracked photo's pairs
    assert any(ids[4] in pair for pair in left)  # one keeps it joined


def test_the_motion_judges_only_pairs_of_one_session_it_can_tell_apart(dataset):
    """Two sessions' poses are not comparable: a wrong track judges only its own session's
    pairs; the drift allowed widens the bound with the distance walked until the direction
    says nothing; the check off drops nothing."""
    from scenebot.sfm.orientation import motion_direction_bound
    from scenebot.sfm.photos import Motion

    db_path, rec = dataset
    spread = np.ptp([rec.image(i).projection_center() for i in rec.reg_image_ids()], axis=0)
    moved = {4: 3.0 * spread * [1.0, -1.0, 0.0]}
    off = drop_pairs_against_orientation(db_path, tracked_photos(rec, moved=moved), 0, 15, 0, 0)
    assert off["motion"]["dropped"] == 0

    def session(k):
        return "round_001" if k == 4 else "round_000"

    alone = tracked_photos(rec, moved=moved, session=session)
    stats = drop_pairs_against_orientation(db_path, alone, 0.0, 15, 30.0, 0.0)
    assert stats["motion"]["checked"] == 36 and stats["motion"]["dropped"] == 0
    a = Motion("s", np.zeros(3), np.eye(3), 0.0)
    b = Motion("s", np.array([1.0, 0.0, 0.0]), np.eye(3), 1.0)
    bound = motion_direction_bound(a, b, 30.0, 0.0)
    assert bound == pytest.approx(30 + math.degrees(math.atan(0.06)))
    far = Motion("s", np.array([1.0, 0.0, 0.0]), np.eye(3), 40.0)
    assert motion_direction_bound(a, far, 30.0, 0.01) == pytest.approx(
        30 + math.degrees(math.atan(1.2))
    )
    assert motion_direction_bound(a, far, 30.0, 0.03) is None  # 3.6 m of drift over 1 m
    assert motion_direction_bound(a, Motion("t", b.center, np.eye(3), 1.0), 30.0, 0.0) is None
