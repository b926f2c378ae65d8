"""Whole localization (real pycolmap SIFT, FLANN, pose) on a ray-cast textured room."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pycolmap
import pytest

from scenebot.localize import (
    FailureReason,
    LocalizationFailure,
    LocalizationMap,
    LocalizeConfig,
    PoseEstimate,
    localize,
    make_localizer,
)
from tests.fixtures.localize import BoxRoom, build_map, camera_rotation


@pytest.fixture(scope="module")
def room_map():
    room = BoxRoom(width=320, height=240, focal_px=260.0, seed=3)
    poses = [(x, y, th) for (x, y) in [(2.0, 2.0), (4.0, 3.0)] for th in np.arange(0, 6.28, 0.8)]
    desc = build_map(room, poses)
    cam = pycolmap.Camera(model="PINHOLE", width=320, height=240, params=[260, 260, 160, 120])
    return room, desc, cam


QUERIES = [(2.6, 2.3, 0.5), (3.4, 2.8, 2.1), (3.0, 2.0, -1.2)]


@pytest.mark.parametrize("method", ["dlt", "pycolmap"])
def test_localization_accuracy(room_map, method):
    room, desc, cam = room_map
    assert len(np.unique(desc.point_ids)) < len(desc.point_ids)  # several rows per point
    cfg = LocalizeConfig(method=method)
    lmap = LocalizationMap(desc, cam, cfg=cfg)
    for x, y, th in QUERIES:
        est = localize(room.render(camera_rotation(th), np.array([x, y, 0.0])), lmap, cfg)
        assert isinstance(est, PoseEstimate), est
        assert np.linalg.norm(est.center - [x, y, 0.0]) < 0.01  # 1 cm
        dth = math.degrees(abs(math.remainder(est.heading - th, 2 * math.pi)))
        assert dth < 0.2
        assert est.num_inliers >= 0.8 * est.num_matches >= 0.8 * cfg.min_matches
        assert set(est.timings_s) == {"extract", "match", "pose", "total"}
        assert est.as_record()["ok"] is True


def test_blank_photo_is_a_typed_failure_not_an_exception(room_map):
    _, desc, cam = room_map
    lmap = LocalizationMap(desc, cam)
    est = localize(np.full((240, 320), 128, np.uint8), lmap)
    assert isinstance(est, LocalizationFailure)
    assert est.reason is FailureReason.TOO_FEW_FEATURES and not est.ok
    # a textured photo of something else: features, but too few matches
    rng = np.random.default_rng(0)
    other = cv2.GaussianBlur((rng.random((240, 320)) * 255).astype(np.uint8), (0, 0), 1.5)
    est = localize(other, lmap)
    assert isinstance(est, LocalizationFailure)
    assert est.reason is not FailureReason.TOO_FEW_FEATURES and est.num_inliers < 12


def test_wrong_photo_size_is_a_clear_error(room_map):
    _, desc, cam = room_map
    with pytest.raises(ValueError, match="map camera is 320x240"):
        localize(np.zeros((480, 640), np.uint8), LocalizationMap(desc, cam))


def test_load_map_folder_and_photo_file(room_map, tmp_path):
    room, desc, cam = room_map
    rec = pycolmap.Reconstruction()
    cam.camera_id = 1
    rec.add_camera(cam)
    rec.write(str(tmp_path))
    np.savez(
        tmp_path / "point_descriptors.npz",
        point_ids=desc.point_ids,
        xyz=desc.xyz,
        descriptors=desc.descriptors,
    )
    lmap = LocalizationMap.load(tmp_path)
    assert (tmp_path / "point_descriptors.flann").exists()
    assert make_localizer(tmp_path).map.index is not None  # second load: from the cache
    make_localizer(tmp_path, cache_file=tmp_path / "elsewhere.flann")
    assert (tmp_path / "elsewhere.flann").exists()
    x, y, th = QUERIES[0]
    photo = tmp_path / "q.jpg"
    cv2.imwrite(
        str(photo),
        room.render(camera_rotation(th), np.array([x, y, 0.0])),
        [cv2.IMWRITE_JPEG_QUALITY, 92],
    )
    est = localize(photo, lmap)
    assert isinstance(est, PoseEstimate)
    assert np.linalg.norm(est.center - [x, y, 0.0]) < 0.02
    with pytest.raises(FileNotFoundError):
        localize(tmp_path / "missing.jpg", lmap)


def test_pose_off_the_camera_plane_or_tilted_is_rejected(room_map):
    room, desc, cam = room_map
    x, y, th = QUERIES[0]
    img = room.render(camera_rotation(th), np.array([x, y, 0.0]))
    lmap = LocalizationMap(desc, cam)
    assert localize(img, lmap).ok  # level camera in the plane z = 0: accepted
    wrong_plane = LocalizeConfig(camera_plane_z_m=0.5)
    est = localize(img, lmap, wrong_plane)
    assert isinstance(est, LocalizationFailure) and est.reason is FailureReason.IMPLAUSIBLE_POSE
    assert "rejected_pose" in est.as_record()
    tilted = LocalizeConfig(camera_pitch_deg=10.0)
    assert localize(img, lmap, tilted).reason is FailureReason.IMPLAUSIBLE_POSE
    unchecked = LocalizeConfig(camera_plane_z_m=None, camera_pitch_deg=None)
    assert localize(img, lmap, unchecked).ok


def test_the_camera_pitch_to_hold_a_fix_to_is_the_maps(room_map):
    """localize.camera_pitch_deg: map (the default): a fix must tilt as the map's photos do
    (LocalizationMap.mount_pitch_deg, the median pitch of the map's photos): a level photo
    fits a level map and not a map of a camera tilted up 10 deg; a photo tilted up 10 deg
    fits that map and not the level one."""
    from scenebot.geometry import look_rotation

    room, desc, cam = room_map
    x, y, th = QUERIES[0]
    level = room.render(camera_rotation(th), np.array([x, y, 0.0]))
    up = room.render(look_rotation(th, math.radians(10.0)), np.array([x, y, 0.0]))
    level_map, tilted_map = (
        LocalizationMap(desc, cam),
        LocalizationMap(desc, cam, mount_pitch_deg=10.0),
    )
    assert localize(level, level_map).ok
    assert localize(level, tilted_map).reason is FailureReason.IMPLAUSIBLE_POSE
    est = localize(up, tilted_map)
    assert est.ok and np.linalg.norm(est.center - [x, y, 0.0]) < 0.02
    assert localize(up, level_map).reason is FailureReason.IMPLAUSIBLE_POSE
    assert localize(up, level_map, LocalizeConfig(camera_pitch_deg=10.0)).ok


def test_a_fix_whose_predicted_error_is_too_large_is_a_failure(room_map):
    """localize.max_position_std_m: the fix says how well its matches determine the centre;
    a bound below that makes it an ``uncertain_pose`` failure, a bound above keeps it."""
    room, desc, cam = room_map
    x, y, th = QUERIES[1]
    img = room.render(camera_rotation(th), np.array([x, y, 0.0]))
    lmap = LocalizationMap(desc, cam)
    est = localize(img, lmap, LocalizeConfig(max_position_std_m=None))
    assert est.ok and 0 < est.position_std_m < 0.01  # a well-determined fix (< 1 cm)
    assert est.as_record()["position_std_m"] == est.position_std_m
    assert localize(img, lmap, LocalizeConfig(max_position_std_m=2 * est.position_std_m)).ok
    tight = localize(img, lmap, LocalizeConfig(max_position_std_m=0.5 * est.position_std_m))
    assert isinstance(tight, LocalizationFailure)
    assert tight.reason is FailureReason.UNCERTAIN_POSE
    # the pose it turned away goes to the log, for the evaluation to judge
    rejected = tight.as_record()["rejected_pose"]
    np.testing.assert_allclose(rejected["center"], est.center, atol=1e-9)
    assert rejected["heading"] == pytest.approx(est.heading)
    assert rejected["position_std_m"] == pytest.approx(est.position_std_m)
