"""Configuration of visual localization (paper section IV.B, "Accurate path-following")."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from scenebot.settings import Settings


class LocalizeConfig(Settings):
    """Settings of SIFT extraction, descriptor matching and absolute pose estimation."""

    method: Literal["dlt", "pycolmap"] = Field(
        "dlt",
        description="Pose solver: 'dlt' (the paper: RANSAC + DLT + RQ + refinement of R, T; "
        "the default) or 'pycolmap' (pycolmap.estimate_and_refine_absolute_pose, P3P "
        "LO-RANSAC, ~50x faster pose step but more confident wrong poses from query SIFT at "
        "first octave 0). Following to the office goals, round 1: dlt at octave 0 fixes "
        "median 1.5 cm, p90 3.7 cm; pycolmap at octave -1 median 1.6 cm, p90 25 cm.",
    )
    sift_first_octave: int = Field(
        0,
        ge=-1,
        le=1,
        description="pycolmap SIFT first octave of the query photo: 0 (default: ~50 ms at "
        "640x480 on 2 cores, the whole localization within the 150 ms budget) or -1 (COLMAP's, "
        "upsampled as the map is built: twice the features, ~180 ms to extract).",
    )
    sift_max_features: int = Field(
        8192, ge=16, description="Largest number of SIFT features kept per query photo."
    )
    sift_num_threads: int = Field(2, ge=-1, description="Threads for SIFT (-1: all cores).")
    flann_trees: int = Field(4, ge=1, description="Randomised KD-trees of the FLANN index.")
    flann_checks: int = Field(
        16,
        ge=1,
        description="Leaves visited per query (best-bin-first search budget); 16 finds the "
        "exact nearest 3D point for ~97% of queries at 2/3 of the time of 32 (~98%).",
    )
    knn: int = Field(
        6,
        ge=2,
        description="Neighbours fetched per query descriptor; the ratio test looks among them "
        "for the nearest descriptor of a different 3D point.",
    )
    ratio: float = Field(
        0.8,
        gt=0.0,
        le=1.0,
        description="Lowe ratio: keep a match when its distance is below ratio times the "
        "distance to the nearest descriptor of a different 3D point.",
    )
    ransac_max_error_px: float = Field(
        4.0, gt=0.0, description="Inlier threshold on the reprojection error (pixels)."
    )
    ransac_confidence: float = Field(
        0.9999, gt=0.0, lt=1.0, description="RANSAC stops when this confident of the best model."
    )
    ransac_max_iterations: int = Field(2000, ge=1, description="RANSAC hypotheses at most.")
    refine_focal: bool = Field(
        False,
        description="DLT method: refine the focal length with R and T as the paper does (its "
        "camera was not calibrated); False keeps the map camera's focal length, which is "
        "markedly more accurate with a calibrated camera (benchmarks/bench_localize.py).",
    )
    min_matches: int = Field(
        20, ge=6, description="Fewer matches than this is a localization failure."
    )
    min_inliers: int = Field(
        20,
        ge=6,
        description="Fewer RANSAC inliers than this is a localization failure (below ~20, "
        "wrong poses from repeated textures become common in the simulated office).",
    )
    max_position_std_m: float | None = Field(
        0.02,
        gt=0,
        description="A pose whose predicted planar error of the camera centre (1 sigma, "
        "worst direction; from the inliers' geometry and reprojection RMSE) exceeds this (m) "
        "is a failure (uncertain_pose): few, far or bunched matches can give a fix tens of cm "
        "off with dozens of inliers. 0.02 keeps 91 of 113 fixes of a default campaign, "
        "error p90 2.4 cm instead of 6.0 cm. None: no check.",
    )
    min_noise_px: float = Field(
        0.5,
        gt=0,
        description="Image noise (pixels) assumed at least, whatever the inliers' RMSE, when "
        "predicting a pose's error (max_position_std_m).",
    )
    camera_plane_z_m: float | None = Field(
        0.0,
        description="z (m, map frame) of the plane the camera moves in (the map convention puts "
        "it at 0); a pose farther than max_height_dev_m from it is rejected. None: no check.",
    )
    max_height_dev_m: float = Field(
        0.05, gt=0, description="Allowed camera height deviation from camera_plane_z_m (m)."
    )
    camera_pitch_deg: float | Literal["map"] | None = Field(
        "map",
        description="The camera's pitch on the robot (deg, positive up); a pose whose optical "
        "axis pitch or whose roll is off by more than max_tilt_deg is rejected. `map`: the "
        "median pitch of the map's photos (the mount as the map measured it; a level camera: "
        "0). None: no check.",
    )
    max_tilt_deg: float = Field(
        1.0,
        gt=0,
        description="Allowed pitch/roll error (deg). Wrong poses from repeated textures are "
        "tilted by degrees; right ones by < 0.2 deg in the simulated office.",
    )
    seed: int = Field(0, description="Random seed of the RANSAC sampling (reproducible runs).")
