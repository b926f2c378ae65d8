"""A person's photos mapped from the camera's tracked motion (scenebot.sfm.tracked), on a
pycolmap synthetic dataset: every pair matched and verified, the true poses known."""

from __future__ import annotations

import numpy as np
import pycolmap
import pytest

from scenebot.geometry import similarity_fit
from scenebot.sfm.config import SfmConfig
from scenebot.sfm.photos import Photo
from scenebot.sfm.place import place_left_out_photos, tracked_source
from scenebot.sfm.tracked import (
    drop_off_tracking,
    map_from_motion,
    pairs_the_tracking_disowns,
    session_to_map,
    tracked_priors,
    tracked_residuals,
    tracked_session,
)
from tests.fixtures.synthetic import synthetic_database, tracked_photos


@pytest.fixture()
def dataset(tmp_path):
    """Twelve photos of 600 points, every pair matched and verified."""
    rec, db_path = synthetic_database(tmp_path, 12, 600)
    return db_path, rec


def centre_errors(model, truth) -> np.ndarray:
    """Camera centre errors of ``model`` after a similarity fit to ``truth`` (true units)."""
    names = {truth.image(i).name: truth.image(i).projection_center() for i in truth.reg_image_ids()}
    ids = list(model.reg_image_ids())
    est = np.array([model.image(i).projection_center() for i in ids])
    true = np.array([names[model.image(i).name] for i in ids])
    s, R, t = similarity_fit(est, true)
    return np.linalg.norm(s * est @ R.T + t - true, axis=1)


def test_photos_placed_at_their_tracked_poses_settle_where_they_were(dataset, tmp_path):
    """Tracked centres 5 cm off at random: every photo registers, the matches pull each
    back to within a centimetre of its true place, every point triangulated."""
    db_path, truth = dataset
    spread = float(np.median(np.ptp([truth.image(i).projection_center()
                                      for i in truth.reg_image_ids()], axis=0)))  # fmt: skip
    photos = tracked_photos(truth, 0.05 * spread / 3.0)
    cfg = SfmConfig(motion_prior_std_m=0.3 * spread / 3.0, num_threads=1)
    res = map_from_motion(db_path, tmp_path, photos, cfg, fix_focal=True)
    assert res is not None and res.mode == "tracked" and res.mapper == "tracked"
    assert res.reconstruction.num_reg_images() == 12 and not res.dropped
    assert res.refinement["session"] == "round_000" and res.refinement["rounds"] >= 1
    before = centre_errors_of_tracking(photos, truth)
    after = centre_errors(res.reconstruction, truth)
    assert np.median(before) > 5 * np.median(after)
    assert np.max(after) < 0.01 * spread
    assert res.reconstruction.num_points3D() > 500
    assert res.reconstruction.compute_mean_reprojection_error() < 1.0


def centre_errors_of_tracking(photos, truth) -> np.ndarray:
    names = {truth.image(i).name: truth.image(i).projection_center() for i in truth.reg_image_ids()}
    est = np.array([p.motion.center for p in photos])
    true = np.array([names[p.name] for p in photos])
    s, R, t = similarity_fit(est, true)
    return np.linalg.norm(s * est @ R.T + t - true, axis=1)


def test_the_largest_session_is_mapped_and_the_others_named(dataset, tmp_path):
    """Photos of another session (another round) or without tracking are not placed; with
    fewer than three tracked photos in a session there is no tracked map."""
    db_path, truth = dataset
    photos = tracked_photos(truth, 0.0, session=lambda k: "round_001" if k >= 9 else "round_000")
    photos[0] = Photo(photos[0].name, photos[0].path)  # no tracking
    assert tracked_session(photos)[0] == "round_000"
    res = map_from_motion(db_path, tmp_path, photos, SfmConfig(num_threads=1), fix_focal=True)
    assert res.reconstruction.num_reg_images() == 8
    assert set(res.dropped) == {photos[k].name for k in (0, 9, 10, 11)}
    assert "round_000" in res.dropped[photos[9].name]
    few = tracked_photos(truth, 0.0, session=lambda k: f"s{k % 6}")
    assert tracked_session(few) is None
    assert map_from_motion(db_path, tmp_path, few, SfmConfig(), fix_focal=True) is None
    assert map_from_motion(db_path, tmp_path, [Photo(p.name, p.path) for p in photos],
                           SfmConfig(), fix_focal=True) is None  # fmt: skip


def test_a_pair_is_disowned_only_between_photos_where_their_tracking_puts_them(dataset):
    """The residuals of a map against the tracking: a photo moved in the map stands out;
    a contradicted pair of two photos in place is a wrong pair, one with the moved photo
    is not."""
    _, truth = dataset
    photos = tracked_photos(truth, 0.0)
    model = pycolmap.Reconstruction(truth)
    ids = sorted(model.reg_image_ids())
    moved = model.image(ids[3])
    pose = moved.cam_from_world()
    model.frame(moved.frame_id).rig_from_world = pycolmap.Rigid3d(
        pose.rotation, np.asarray(pose.translation) + np.array([1.0, 0.0, 0.0])
    )
    res = tracked_residuals(model, photos)
    assert len(res) == 12 and res[moved.name] > 0.9
    assert max(v for k, v in res.items() if k != moved.name) < 1e-6
    a, b = model.image(ids[0]).name, model.image(ids[1]).name
    pairs = [(a, b, 50, 0.0), (a, moved.name, 40, 0.1)]
    assert pairs_the_tracking_disowns(pairs, res, 0.3) == [(a, b)]


def test_a_person_map_failing_its_check_is_mapped_again_from_the_tracking_first(dataset):
    """The person check's other maps: from the tracked motion first, when photos have it
    and the failing map was not that one; then global SfM and the incremental seeds."""
    from types import SimpleNamespace

    from scenebot.sfm.stage import _person_remaps

    _, truth = dataset
    check = SimpleNamespace(stats={"pairs": {"turned_in_place_photos": 0}})

    def ways(photos, mapper, **cfg):
        s = SimpleNamespace(cfg=SfmConfig(**cfg), photos=photos)
        return [how for how, _ in _person_remaps(s, check, 12, mapper)]

    tracked = tracked_photos(truth, 0.0)
    assert ways(tracked, "incremental")[:2] == ["from the tracked motion", "global SfM"]
    assert ways(tracked, "tracked")[0] == "global SfM"
    assert ways(tracked, "incremental", motion_map=False)[0] == "global SfM"
    assert ways([Photo(p.name, p.path) for p in tracked], "incremental")[0] == "global SfM"


def moved_by(model: pycolmap.Reconstruction, iid: int, shift) -> None:
    """Register image ``iid`` of ``model`` ``shift`` (map units) from where it is (its
    rotation kept: a repeating texture matched one motif along)."""
    im = model.image(iid)
    R = im.cam_from_world().rotation.matrix()
    centre = im.projection_center() + np.asarray(shift, float)
    model.frame(im.frame_id).rig_from_world = pycolmap.Rigid3d(pycolmap.Rotation3d(R), -R @ centre)


def test_a_sessions_frame_is_found_from_its_photos_despite_one_registered_off(dataset):
    """The session-to-map similarity from the registered photos: rotation, scale and
    translation of the fixture's tracking (30 deg, shifted) recovered with one photo
    registered 1 m off; too few photos give none."""
    _, truth = dataset
    photos = tracked_photos(truth, 0.0)
    model = pycolmap.Reconstruction(truth)
    ids = sorted(model.reg_image_ids())
    moved_by(model, ids[4], [1.0, 0.0, 0.0])
    s, R, t, used = session_to_map(model, photos)
    assert s == pytest.approx(1.0, abs=0.02)
    c, sn = np.cos(0.5), np.sin(0.5)
    assert np.allclose(R, np.array([[c, -sn, 0], [sn, c, 0], [0, 0, 1]]).T, atol=1e-6)
    assert len(used) == 12  # the moved photo's rotation is right: it votes
    for p in photos:
        if p.name != model.image(ids[4]).name:
            im = model.find_image_with_name(p.name)
            assert np.linalg.norm(s * R @ p.motion.center + t - im.projection_center()) < 0.1
    assert session_to_map(model, photos[:1]) is None


def test_a_photo_registered_off_its_tracking_leaves_and_is_placed_back(dataset, tmp_path):
    """A photo registered 1.5 m off its tracked pose leaves the map (the others stay); placed
    again at its tracked pose (the session brought onto the map by the others), its matches
    pull it back to its true place."""
    db_path, truth = dataset
    spread = float(np.median(np.ptp([truth.image(i).projection_center()
                                      for i in truth.reg_image_ids()], axis=0)))  # fmt: skip
    photos = tracked_photos(truth, 0.02 * spread / 3.0)
    model = pycolmap.Reconstruction(truth)
    ids = sorted(model.reg_image_ids())
    name = model.image(ids[5]).name
    moved_by(model, ids[5], [0.5 * spread, 0.0, 0.0])
    cfg = SfmConfig(motion_prior_std_m=0.1 * spread, num_threads=1)
    off = drop_off_tracking(model, photos, 3 * cfg.motion_prior_std_m)
    assert list(off) == [name] and off[name] > 0.4 * spread
    assert model.num_reg_images() == 11
    dropped = {name: "registered off its tracking", "no_such.jpg": "not in the database"}
    priors, why = tracked_priors(model, photos, set(dropped))
    assert list(priors) == [name] and why == {}
    true_centre = truth.find_image_with_name(name).projection_center()
    prior_centre = priors[name].rotation.matrix().T @ -np.asarray(priors[name].translation)
    assert np.linalg.norm(prior_centre - true_centre) < 0.05 * spread
    placed = place_left_out_photos(model, db_path, tmp_path, photos, dropped, priors,
                                   tracked_source(cfg), cfg)  # fmt: skip
    assert placed["kept"] == [name] and placed["source"] == "its tracked motion"
    assert name not in dropped and model.num_reg_images() == 12
    back = model.find_image_with_name(name).projection_center()
    assert np.linalg.norm(back - true_centre) < 0.01 * spread


def test_a_session_with_one_registered_photo_gives_no_priors(dataset):
    _, truth = dataset
    photos = tracked_photos(truth, 0.0, session=lambda k: "round_001" if k >= 10 else "round_000")
    photos[0] = Photo(photos[0].name, photos[0].path)  # no tracking
    model = pycolmap.Reconstruction(truth)
    gone = photos[11].name
    model.deregister_frame(model.find_image_with_name(gone).frame_id)
    priors, why = tracked_priors(model, photos, {gone, photos[0].name, photos[3].name})
    assert set(priors) == {photos[3].name}
    assert "round_001" in why[gone] and why[photos[0].name] == "no tracked motion"


def test_every_session_has_residuals_in_the_trackings_metres(dataset):
    """Residuals for the photos of every session (a pair between a round-0 photo and a
    round-1 photo is judged too), in the tracking's scale whatever the map's."""
    _, truth = dataset
    photos = tracked_photos(truth, 0.0, session=lambda k: "round_001" if k >= 6 else "round_000")
    model = pycolmap.Reconstruction(truth)
    model.transform(pycolmap.Sim3d(3.0, pycolmap.Rotation3d(), np.zeros(3)))  # any scale
    ids = sorted(model.reg_image_ids())
    moved_by(model, ids[8], [3.0, 0.0, 0.0])  # 1 m in the tracking's metres
    res = tracked_residuals(model, photos)
    assert len(res) == 12
    assert res[model.image(ids[8]).name] == pytest.approx(1.0, rel=0.05)
    assert max(v for k, v in res.items() if k != model.image(ids[8]).name) < 1e-6
