"""The localization gate's count (capture/predict.py): map points a photo from a robot pose
could match, on a small hand-made map in the robot frame."""

from __future__ import annotations

import math

import numpy as np
import pycolmap
import pytest

from scenebot.capture.predict import MatchPredictor
from scenebot.geometry import look_rotation
from scenebot.robot.base import Pose2D
from scenebot.score.config import ScoreConfig

W, H, F = 160, 120, 140.0
FWD = 0.1


def wall_map(folder, pitch_deg: float = 0.0):
    """Two photos 0.5 m apart facing +x (heading 0, camera ``FWD`` ahead of the robot's axis,
    tilted up by ``pitch_deg``) and 120 points on the wall x = 2.5 both of them see."""
    rec = pycolmap.Reconstruction()
    cam = pycolmap.Camera(
        model="PINHOLE", width=W, height=H, params=[F, F, W / 2, H / 2], camera_id=1
    )
    rec.add_camera_with_trivial_rig(cam)
    p = math.radians(pitch_deg)
    tilt = np.array([[1, 0, 0], [0, math.cos(p), math.sin(p)], [0, -math.sin(p), math.cos(p)]])
    R = tilt @ look_rotation(0.0)  # the optical axis raised by the pitch
    centres = [np.array([FWD, 0.0, 0.0]), np.array([FWD, 0.5, 0.0])]
    ys, zs = np.meshgrid(np.linspace(-0.3, 0.8, 12), np.linspace(-0.2, 0.4, 10))
    pts = np.stack([np.full(ys.size, 2.5), ys.ravel(), zs.ravel()], 1)
    kps = []
    for c in centres:
        x = (pts - c) @ R.T
        kps.append(np.c_[F * x[:, 0] / x[:, 2] + W / 2, F * x[:, 1] / x[:, 2] + H / 2])
    for i, c in enumerate(centres):
        im = pycolmap.Image(name=f"r000_{i:04d}.jpg", keypoints=kps[i], camera_id=1,
                            image_id=i + 1)  # fmt: skip
        rec.add_image_with_trivial_frame(im, pycolmap.Rigid3d(pycolmap.Rotation3d(R), -R @ c))
    for k, X in enumerate(pts):
        track = pycolmap.Track()
        track.add_element(1, k)
        track.add_element(2, k)
        rec.add_point3D(X, track, np.array([128, 128, 128], np.uint8))
    rec.write_binary(str(folder))
    return len(pts)


def predictor(folder):
    sc = ScoreConfig()
    return MatchPredictor(folder, sc.match_angle_deg, sc.match_scale_ratio, sc.near_m, FWD, 0.0)


@pytest.mark.parametrize("pitch_deg", [0.0, 12.0])
def test_a_photo_facing_the_mapped_wall_could_match_it_one_facing_away_nothing(tmp_path, pitch_deg):
    n = wall_map(tmp_path, pitch_deg)
    pred = predictor(tmp_path)
    assert pred.pitch == pytest.approx(math.radians(pitch_deg), abs=1e-9)  # the mount
    assert pred.height == pytest.approx(0.0, abs=1e-9)
    assert pred(Pose2D(0.0, 0.0, 0.0)) == n  # where the photos were taken
    assert pred(Pose2D(0.0, 0.25, 0.0)) > 0.8 * n  # between them
    assert pred(Pose2D(0.0, 0.0, math.pi)) == 0  # facing away
    assert pred(Pose2D(0.0, 0.0, math.pi / 2)) == 0  # along the wall
    # 60 deg from how the map saw the wall (score.match_angle_deg 45): SIFT would not match
    assert pred(Pose2D(2.5 - 1.2 * math.cos(math.radians(60)), -2.0, math.radians(60))) == 0
    # five times as far as the map's photos (score.match_scale_ratio 2): too small to match
    assert pred(Pose2D(-9.5, 0.0, 0.0)) == 0
