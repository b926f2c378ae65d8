"""Which localization photos could localize: the map points a photo from the robot's pose
estimate could match, counted before the photo is taken.

A localization photo joins the map through SIFT matches to the map's 3D points. In the
adaptive rounds of the office (2026-11-27, 381ed2a; rounds 1-6, 711 localization photos) 353
of them failed, facing a bare wall or what the map saw only from elsewhere, and each failure
cost a photo (a render in the simulator, seconds over Bluetooth for the NXT), a SIFT
extraction and a RANSAC that ran all its hypotheses. Counted from the pose estimate as the
goals stage counts a goal's view (:func:`scenebot.score.matchable.matchable_points`: the
points in view, seen within ``score.match_angle_deg`` and a factor
``score.match_scale_ratio`` of distance of how the map's photos saw them), the failures
held a median of 37 such points (quartiles 7 and 339) and the fixes 1,018 (500 and 1,692);
below 10 lay 104 of the 353 failures and 4 of the 338 fixes. The follower
(:meth:`scenebot.capture.follow.PathFollower.localize_now`) takes no photo below
``follow.min_matchable_points``.

The camera's pose relative to the map comes from the map itself: its height is the median
height of the map's camera centres (the camera plane of a robot's map), its pitch the
median pitch of the map's photos (the mount), its position ``follow.camera_forward_m`` and
``camera_left_m`` from the robot's axis, its heading the robot's.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from scenebot.geometry import mount_pitch, read_sparse_map
from scenebot.robot.base import Pose2D
from scenebot.score.geometry import person_views
from scenebot.score.matchable import matchable_points

SCORE_SETTINGS = ("match_angle_deg", "match_scale_ratio", "near_m")
"""The ``score`` settings the count reads: the adaptive capture receives these alone, so that
a change to the score's other settings re-decides the goals but never re-takes a finished
round's photos (``rules/common.smk``, ``adaptive_capture_params``)."""


class MatchPredictor:
    """``pose -> map points a photo from there could match`` for one map.

    Args:
        sfm_dir: the map (a COLMAP model in the robot frame).
        match_angle_deg: ``score.match_angle_deg``.
        match_scale_ratio: ``score.match_scale_ratio``.
        near_m: ``score.near_m``.
        forward_m: camera centre ahead of the robot's axis (m).
        left_m: camera centre left of the robot's axis (m).
    """

    def __init__(
        self,
        sfm_dir: Path,
        match_angle_deg: float,
        match_scale_ratio: float,
        near_m: float,
        forward_m: float,
        left_m: float,
    ):
        smap = read_sparse_map(sfm_dir)
        self.xyz, self.view_dir, self.view_dist = smap.xyz, smap.view_dir, smap.view_dist
        self.intr = smap.intrinsics[0]
        self.pitch = mount_pitch(smap.R)
        self.height = float(np.median(smap.centres[:, 2]))
        self.match_angle_deg = match_angle_deg
        self.match_scale_ratio = match_scale_ratio
        self.near_m = near_m
        self.forward_m, self.left_m = forward_m, left_m

    def __call__(self, pose: Pose2D) -> int:
        c, s = math.cos(pose.theta), math.sin(pose.theta)
        x = pose.x + self.forward_m * c - self.left_m * s
        y = pose.y + self.forward_m * s + self.left_m * c
        views = person_views(np.array([[x, y, self.height, pose.theta, self.pitch]]), self.intr)
        return int(
            matchable_points(
                views, self.intr.width, self.intr.height, self.xyz, self.view_dir,
                self.view_dist, self.match_angle_deg, self.match_scale_ratio, self.near_m,
            )[0]
        )  # fmt: skip
