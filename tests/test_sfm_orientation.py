"""Pairs of photos their cameras' orientation contradicts (scenebot.sfm.orientation), on a
pycolmap synthetic dataset: every pair verified, the true poses known."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pycolmap
import pytest

from scenebot.sfm.orientation import drop_pairs_against_orientation, rotation_from_orientation
from scenebot.sfm.photos import Photo
from tests.fixtures.synthetic import synthetic_database


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
