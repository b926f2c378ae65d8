"""Configuration of the sfm stage (merged by the lead into the single campaign config)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from scenebot.settings import Settings


class KnownDistance(Settings):
    """A known distance between the camera centres of two photos (bring-your-own photos)."""

    image_a: str = Field(description="File name of the first photo (as in the photo folder).")
    image_b: str = Field(description="File name of the second photo.")
    distance_m: float = Field(gt=0.0, description="Distance between their camera centres (m).")


class UpPhoto(Settings):
    """The side of one photo that points up (bring-your-own photos): overrides the up
    direction estimated from the photos."""

    image: str = Field(description="File name of the photo (as in the photo folder).")
    side: Literal["top", "bottom", "left", "right"] = Field(
        "top",
        description=(
            "The side of that photo that points up: top for a photo held upright, left or "
            "right for one turned 90 degrees, bottom for one upside down. The frame tilts "
            "with that photo's own tilt (pick one taken level)."
        ),
    )


class SfmConfig(Settings):
    """Settings of structure from motion (``scenebot.sfm.stage.run``)."""

    # --- features -------------------------------------------------------------------------
    max_num_features: int = Field(
        4096, ge=256, description="SIFT features kept per photo (pycolmap extraction)."
    )
    max_image_size: int = Field(
        1600, ge=64, description="Photos are downscaled to this longest side (px) for SIFT."
    )
    peak_threshold: float = Field(
        0.0067,
        gt=0.0,
        description=(
            "SIFT contrast threshold (pycolmap default 0.0067); lower finds more features "
            "on low-contrast surfaces and small photos."
        ),
    )
    domain_size_pooling: bool = Field(
        False,
        description="DSP-SIFT (pycolmap's domain-size pooling): steadier descriptors, slower.",
    )
    fallback_focal_factor: float = Field(
        1.2,
        gt=0.1,
        description=(
            "Focal length (px) assumed for photos whose EXIF has no usable focal, as a factor "
            "of the longest image side (COLMAP's default 1.2); refined by bundle adjustment."
        ),
    )
    camera_model: str = Field(
        "SIMPLE_RADIAL", description="COLMAP camera model of every camera (SIMPLE_RADIAL, ...)."
    )
    fix_exif_focal: bool = Field(
        True,
        description=(
            "Keep the focal length (px) fixed at the EXIF value when every photo's EXIF gives "
            "FocalLength and FocalPlaneResolution (a calibrated or simulated camera). Circles "
            "of photos turned in place couple the focal length with the cameras' forward "
            "position: a refined focal 0.3 % low put the cameras ~1.3 cm too far out. Focals "
            "from the 35 mm equivalent (rounded) or sfm.fallback_focal_factor are refined."
        ),
    )
    refine_distortion: bool = Field(
        True,
        description="Bundle adjustment refines the radial distortion of the camera model.",
    )
    num_threads: int = Field(-1, description="Threads for extraction/matching/mapping (-1: all).")

    # --- pairs ----------------------------------------------------------------------------
    exhaustive_max_images: int = Field(
        40,
        ge=0,
        description="Photo sets up to this size are matched exhaustively (all pairs); "
        "robot: guided and person-sim: 250 unless set (a person's new photos have no "
        "position to choose their partners by).",
    )
    spatial_neighbors: int = Field(
        20, ge=0, description="Nearest photos by logged position (odometry/localization) per photo."
    )
    spatial_max_distance_m: float = Field(
        3.0, gt=0.0, description="Spatial neighbours farther than this (m) are not paired."
    )
    sequential_overlap: int = Field(
        5, ge=0, description="Each photo is paired with the next N photos of the same round."
    )
    loop_closure_pairs: int = Field(
        3, ge=0, description="Long-range candidate pairs per photo (evenly spread over the set)."
    )
    min_num_matches: int = Field(
        15, ge=5, description="Minimum verified inlier matches for a pair to be used in mapping."
    )

    # --- mapping --------------------------------------------------------------------------
    incremental: bool = Field(
        True,
        description=(
            "Round r > 0 starts from round r-1's model and registers only the new photos "
            "(from-scratch fallback when too few register)."
        ),
    )
    min_registered_share: float = Field(
        0.8,
        ge=0.0,
        le=1.0,
        description=(
            "Fail with a clear message when fewer than this share of photos registers; in a "
            "round after the first, only when the map also keeps less than this share of the "
            "previous map's photos (else the round's photos did not join it: report.json "
            "short_round, and the goals stage's stuck rule stops a campaign that keeps "
            "failing so)."
        ),
    )
    random_seed: int = Field(0, description="Seed for pycolmap's RANSAC and pair sampling.")
    mapping_attempts: int = Field(
        3,
        ge=1,
        description=(
            "Mapping from scratch runs again with another seed (random_seed + 1, + 2, ...) "
            "while fewer than min_registered_share of the photos register, up to this many "
            "runs; the largest model wins. Incremental mapping picks its initial pair and "
            "RANSAC samples at random, and on weakly overlapping sets a run can split the "
            "model where the next one does not."
        ),
    )
    global_sfm_fallback: Literal["photos", "always", "never"] = Field(
        "photos",
        description=(
            "Mapping from scratch: when the incremental mapper leaves out photos that "
            "verified pairs connect to its model, global SfM (pycolmap's GLOMAP: rotation "
            "averaging and global positioning over every verified pair) maps the set too, "
            "and the model that registers more photos is kept (report.json global_sfm). The "
            "incremental mapper registers a photo only when it sees >= 30 points already "
            "triangulated by two registered photos; across a wide gap between views too few "
            "features are seen three times (temple ring: 3 of 16 photos saw 5-21 and formed "
            "a 4-photo model that COLMAP discards; global SfM registered 16). `photos`: only "
            "for a photo folder (robot: photos). The robot's circles of photos turned in "
            "place are near-pure rotations, which global positioning does not handle: on the "
            "canned office set it registered 45 of 45 photos against 42 with the metric "
            "scale 103 % off. `always`, `never`: for every photo set, or none."
        ),
    )
    global_max_disagreement: float = Field(
        0.05,
        gt=0.0,
        description=(
            "The global model is kept only where it agrees with the incremental one on the "
            "photos both registered: the median distance between their camera centres after "
            "a similarity fit, as a share of the incremental cameras' median distance from "
            "their centroid, at most this. Global positioning of photos turned in place can "
            "fold a map (the canned office photos as a folder: points 2,000 km out) while "
            "registering more photos; the two models of the temple agree within ~0.2 %."
        ),
    )
    global_ba_ratio: float = Field(
        1.1,
        ge=1.01,
        description=(
            "Incremental mapping runs a global bundle adjustment whenever the model grew by "
            "this factor (COLMAP default 1.1; 1.5 was not faster across scenes: round 0 of "
            "the office 157 s against 176 s, of the flat 139 s against 111 s)."
        ),
    )
    update_global_ba_ratio: float = Field(
        3.0,
        ge=1.01,
        description=(
            "Like global_ba_ratio, when continuing from the previous round's model: the old "
            "photos are already adjusted, and the final refinement adjusts everything."
        ),
    )
    max_estimate_deviation_m: float = Field(
        0.5,
        description=(
            "A photo registered farther than this (m) from where the robot estimated it took "
            "it (adaptive rounds log a map-frame estimate per photo) is left out of the map, "
            "named in the log and report.json; 0 turns the check off."
        ),
    )
    max_compass_deviation_deg: float = Field(
        12.0,
        ge=0.0,
        description=(
            "With sfm.use_compass: a photo registered with a heading farther than this "
            "(deg) from its compass reading is left out of the map (a wrong rotation; its "
            "position is wrong too), named in the log and report.json; 0 turns it off."
        ),
    )
    orientation_max_deg: float = Field(
        0.0,
        ge=0.0,
        description=(
            "Photos whose log records the camera's orientation (a phone's compass and "
            "accelerometer; robot: person-sim): a verified pair whose relative rotation, as "
            "its matches give it, differs by more than this (deg) from the one the two "
            "photos' orientations give is not used in mapping (a repeated texture's copy "
            "elsewhere, seen facing another way; report.json orientation_pairs), unless the "
            "photos need it to stay joined. 35 is 2.5 sigma of the difference of two readings "
            "of a compass good to 10 deg; a pair dropped stays out of the scene database. 0 "
            "(the default): off. On, it maps the flat's person walk right (77 of 80, none off, "
            "against 68 with 28 off), but a sparse walk's pairs whose pose is ill-determined "
            "(the office at 320 x 240, 32 photos) go too and the walk falls apart."
        ),
    )
    motion_max_deg: float = Field(
        30.0,
        ge=0.0,
        lt=90.0,
        description=(
            "Photos whose log records the camera's tracked motion (a phone's visual-inertial "
            "odometry, `motion`; robot: person-sim): a verified pair of one tracking session "
            "whose relative translation, as its matches give it, points more than this (deg) "
            "away from the tracked one, plus the angle the tracking's drift allows "
            "(sfm.motion_drift), or whose relative rotation differs from the tracked one by "
            "more than this, is not used in mapping (a repeating texture matched one motif "
            "along: the right rotation, the wrong translation; report.json "
            "orientation_pairs.motion), unless the photos need it to stay joined. 0: off."
        ),
    )
    motion_drift: float = Field(
        0.03,
        ge=0.0,
        description=(
            "The drift sfm.motion_max_deg allows a tracked position: this fraction of the "
            "distance the camera was carried between two photos (standard deviation; three "
            "of them widen the bound). Phones' visual-inertial odometry drifts 1-3% indoors."
        ),
    )
    motion_map: bool = Field(
        True,
        description=(
            "A person's photos whose log records the camera's tracked motion (a phone's "
            "visual-inertial odometry, `motion`): the first map of them starts from the "
            "tracked poses of the session most of them belong to (triangulated between "
            "them, bundle-adjusted with a position prior at the tracked centre: "
            "scenebot.sfm.tracked), instead of the incremental mapper's, which repeating "
            "texture folds (the flat's walk through every room: every photo 0.8-1.3 m off "
            "within its own room, against a median of 0.3 cm and none beyond 16 cm); the "
            "other photos are then registered into it. false: the incremental mapper."
        ),
    )
    motion_prior_std_m: float = Field(
        0.3,
        gt=0.0,
        description=(
            "sfm.motion_map: standard deviation (m) of the position prior at each photo's "
            "tracked centre in the bundle adjustments (the tracking's drift over a walk of "
            "a few tens of metres)."
        ),
    )
    place_left_out_photos: bool = Field(
        False,
        description=(
            "Photos the map leaves out (not registered, or registered beyond "
            "max_estimate_deviation_m / max_compass_deviation_deg of the robot's estimate: "
            "repeating texture) that have a robot estimate are placed at it, registered, "
            "triangulated with the map and with each other, and bundle-adjusted with a "
            "position prior (place_prior_std_m), the map's points held; one stays when as "
            "many observations agree with it as the mapper asks of any registration, its "
            "group of placed photos matches as many of the map's own points, and it is still "
            "within the tolerances (scenebot.sfm.place). Off by default: on the f9d0320 "
            "flat's final round it brought back 9-10 of 29 left-out photos, 0.1-2 cm and up to "
            "1 deg from the truth (they see walls the map's photos do not, so their group "
            "is held by few map points), and the dense model came out 19.9% complete at 2 cm "
            "with 83.2% accuracy against 20.7% and 85.2% without them (docs/results.md)."
        ),
    )
    place_tracked_photos: bool = Field(
        True,
        description=(
            "A person's photos the map leaves out (not registered: a close-up of a repeating "
            "wallpaper) that have a tracked motion (the capture log's motion) are placed as "
            "place_left_out_photos places a robot's, at the pose their tracking gives once "
            "the registered photos of their tracking session bring its frame onto the map "
            "(scenebot.sfm.tracked.tracked_priors), with the position prior and tolerance "
            "sfm.motion_prior_std_m and the heading's sfm.max_compass_deviation_deg."
        ),
    )
    place_prior_std_m: float = Field(
        0.03,
        gt=0.0,
        description=(
            "With place_left_out_photos: standard deviation (m) of the position prior at "
            "the robot's estimate (its visual fixes against the map: median 0.2-0.6 cm, "
            "p90 1-3 cm per round in the office and the flat)."
        ),
    )
    update_keep_previous_poses: bool = Field(
        True,
        description=(
            "In a round update, the final refinement and the circle adjustment keep the "
            "previous round's photo poses fixed: the map grows without bending what the robot "
            "and later stages already used (false: adjust everything)."
        ),
    )
    update_fix_existing: bool = Field(
        True,
        description=(
            "Keep the previous round's poses fixed while registering new photos (faster); "
            "the final refinement still adjusts all poses."
        ),
    )
    register_new_photos: bool = Field(
        True,
        description=(
            "Round r > 0: register the new photos into round r-1's map (absolute pose from "
            "their matches to its points, the robot's estimate as a second starting pose and "
            "a gate against it, triangulation, local bundle adjustment; the previous photos' "
            "poses and the intrinsics held) and refine only them robustly; the global "
            "refinement (sfm.retriangulate, sfm.refine_iterations over the whole map) runs "
            "only when sfm.max_residual_ratio or sfm.max_fix_offset_m say so. Falls back to "
            "the incremental mapper when fewer than min_registered_share of the new photos "
            "are registered, taken out against the robot's estimate, or out of reach (fewer "
            "map matches than a registration needs). False: the incremental mapper and the "
            "global refinement every round. Measured 2026-11-27 (benchmarks/"
            "bench_sfm_rounds.py on the f9d0320 office and flat campaigns, same run): office "
            "rounds 3 and 6 in 42 and 46 s instead of 157 and 247 s, flat rounds 1 and 3 in "
            "54 and 39 s instead of 55 and 86 s, as many photos within 3, 13 photos more than "
            "25 cm off instead of 26; the dense model of the last round's map 88.2 / 96.6 % "
            "(office) and 20.8 / 86.6 % (flat) complete / accurate at 2 cm against 87.7 / "
            "96.6 and 20.7 / 85.2 % (issue 22)."
        ),
    )
    register_ba_function_tolerance: float = Field(
        1e-5,
        gt=0.0,
        description=(
            "With sfm.register_new_photos: the robust bundle adjustment of the new photos "
            "stops when an iteration lowers the cost by less than this share (Ceres "
            "function_tolerance; 0 would run to 100 iterations: office round 6, the first "
            "adjustment 101 iterations and 3x the time for the same poses to 0.1 mm)."
        ),
    )
    max_residual_ratio: float = Field(
        1.25,
        gt=1.0,
        description=(
            "With sfm.register_new_photos: the global refinement runs when the median "
            "reprojection error of the new photos' observations exceeds this multiple of "
            "that of the previous photos' observations of the same points (after the new "
            "photos' refinement, both filtered at refine_max_error_px): the held map cannot "
            "explain the new views. Freshly fitted, the new observations err less (office "
            "rounds 1-6: 0.75-0.96)."
        ),
    )
    max_fix_offset_m: float = Field(
        0.05,
        ge=0.0,
        description=(
            "With sfm.register_new_photos: the global refinement runs when the new photos "
            "registered farther than this (m) from where the robot's visual localization "
            "fix of each photo put its camera, in the median over the new photos with a fix "
            "of their own (3 at least). Fixes at localize.max_position_std_m = 0.02 m err "
            "by 2.4 cm in the median (planar, Rayleigh); office rounds 1-6: 0.5-1.8 cm. "
            "0 turns the check off."
        ),
    )
    retriangulate: bool = Field(
        True,
        description=(
            "After mapping, re-triangulate all tracks from the database with the registered "
            "poses (full tracks; removes the previous round's pruning) before refinement."
        ),
    )
    refine_iterations: int = Field(
        3,
        ge=0,
        description=(
            "Rounds of the final robust refinement (drop observations beyond "
            "refine_max_error_px, Cauchy-loss global bundle adjustment); 0 = off."
        ),
    )
    refine_max_error_px: float = Field(
        1.0, gt=0.0, description="Reprojection error (px) beyond which observations are dropped."
    )

    # --- robot frame ----------------------------------------------------------------------
    camera_yaw_deg: float = Field(
        0.0,
        description=(
            "Yaw of the camera's optical axis relative to the robot's forward axis (deg, "
            "counter-clockwise); 0 = the camera looks where the robot drives."
        ),
    )
    use_compass: bool = Field(True, description="Heading of the robot frame from the compass.")
    camera_offset_m: float | None = Field(
        None,
        gt=0.0,
        description=(
            "The camera centre's known distance (m) from the robot's rotation axis (its "
            "mount, measured once; unset in a campaign config: from sim.camera). When set, "
            "metric scale comes from the circles of photos turned in place (their camera "
            "centres lie on circles of this radius, robust to wheel slip); odometry drive "
            "distances are the fallback and a cross-check reported in report.json."
        ),
    )
    min_circle_photos: int = Field(
        8,
        ge=3,
        description=(
            "Fewest registered photos of one turn-in-place circle (spanning >= 90 deg of "
            "heading) for it to count in the lever-arm scale (sfm.camera_offset_m)."
        ),
    )
    max_circle_residual: float = Field(
        0.3,
        gt=0.0,
        description=(
            "A turn-in-place circle counts in the lever-arm scale only when its photos lie, "
            "in the median, within this share of its radius from the circle fitted to them "
            "(office at 640x480: 3-14 %; at 320x240 with 17 photos per circle 60-75 %, and "
            "a scale 45 % off). Without a usable circle the scale comes from odometry."
        ),
    )
    circle_prior_std_m: float = Field(
        0.005,
        ge=0.0,
        description=(
            "With sfm.camera_offset_m: standard deviation (m) of the position prior that "
            "holds every photo of a turn-in-place circle on its circle (axis from the model, "
            "radius the lever arm) in a final bundle adjustment; 0 = off."
        ),
    )
    circle_max_residual_m: float = Field(
        0.02,
        gt=0.0,
        description=(
            "Photos farther than this (m) from their turn-in-place circle are moved back "
            "onto it before that adjustment (misregistered runs of a circle)."
        ),
    )
    circle_prior_iterations: int = Field(
        2, ge=1, description="Rounds of circle re-fit and prior bundle adjustment."
    )
    max_circle_scale_spread: float = Field(
        0.05,
        gt=0.0,
        description=(
            "With sfm.camera_offset_m: when the circles of photos turned in place, each "
            "fitted on its own, give metric scales further apart than this share (max - "
            "min over their mean) on a map mapped from scratch, the map is bent (runs of a "
            "circle misregistered: in the office a 10 % spread came with a 2.5 % scale error, "
            "1-3 % spreads with 0.1-0.5 %) and mapping runs again with another seed, up to "
            "sfm.scale_remap_attempts times; the map whose circles agree best is kept."
        ),
    )
    scale_remap_attempts: int = Field(
        2,
        ge=0,
        description=(
            "Extra mapping runs (seeds after those of sfm.mapping_attempts) when the circles "
            "disagree on the scale (sfm.max_circle_scale_spread); 0 = never re-map."
        ),
    )
    min_odometry_pairs: int = Field(
        5, ge=2, description="Consecutive photo pairs needed to fit the metric scale to odometry."
    )
    known_distance: KnownDistance | None = Field(
        None,
        description=(
            "Bring-your-own photos: a measured distance between two camera centres sets the "
            "metric scale (otherwise scale 1, arbitrary units)."
        ),
    )
    up_photo: UpPhoto | None = Field(
        None,
        description=(
            "Bring-your-own photos: up is this side of this photo, instead of the up "
            "estimated from the photos (the direction most perpendicular to the optical axes "
            "and the camera offsets, signed by the image-up vectors when informative, else "
            "so that the cameras look down; report.json alignment.stats.up). Set it when "
            "map.png shows the map tilted or upside down."
        ),
    )
    person_min_pair_share: float = Field(
        0.25,
        ge=0.0,
        le=1.0,
        description=(
            "A person's map (robot: photos, guided, person-sim) is checked without the "
            "truth (report.json person_check): a geometrically verified pair of photos (>= 30 "
            "inlier matches whose rays the map makes meet at >= 4 deg) whose matches the map "
            "holds as one 3D point for less than this "
            "share of the median pair's share contradicts the map (a fold, or a photo "
            "registered off: office walks 0-16 % at the folds, >= 30 % on every pair of maps "
            "right within a few cm, median 70-80 %); a median pair below 30 % fails the map "
            "as a whole. A map that fails is mapped again (global SfM unless a quarter of "
            "the photos turned in place, then sfm.person_remap_attempts seeds); 0 turns the "
            "check off."
        ),
    )
    person_height_std_m: float = Field(
        0.1,
        ge=0.0,
        description=(
            "Guided campaigns (robot: guided, person-sim): round 0 is a walk around the room, "
            "standing, and its camera centres lie within this standard deviation (m) of one "
            "plane. A round-0 photo more than 4 times this off the robust plane of the others "
            "is registered off, and a spread of more than 2 times this says the map is bent "
            "(report.json person_check.plane); the plane's normal is the frame's up. "
            "person-sim: its person_sim.height_std_m unless set. 0 turns the plane off."
        ),
    )
    person_shot_distance_m: float = Field(
        1.0,
        ge=0.0,
        description=(
            "Guided rounds (robot: guided, person-sim): each new photo was taken for one of "
            "the previous round's shots (its goals.json), so a pose farther than this (m) "
            "from every shot, or turned more than sfm.person_shot_heading_deg from each "
            "near one, is suspect: the photo's pose is estimated again from the matches a "
            "camera near each shot could have made (as the robot's estimate gates an "
            "adaptive photo, sfm.max_estimate_deviation_m) and the pose near a shot with "
            "the most inliers replaces it; a photo with no such pose keeps its own (taken "
            "away from the guide, it still adds to the map). A person stands about 0.2 m and "
            "10 deg from a shot (person_sim); 0 turns the shots' check off."
        ),
    )
    person_shot_heading_deg: float = Field(
        40.0,
        ge=0.0,
        description="See sfm.person_shot_distance_m: the heading tolerance (deg).",
    )
    person_remap_attempts: int = Field(
        2,
        ge=0,
        description=(
            "When a person's map fails its check (sfm.person_min_pair_share, "
            "sfm.person_height_std_m): after global SfM, incremental mapping runs again from "
            "scratch with up to this many other seeds; the map the check finds least wrong "
            "is kept, photos it still names are left out (down to "
            "sfm.min_registered_share), else the stage stops with the check's reasons."
        ),
    )

    # --- outputs --------------------------------------------------------------------------
    plots: bool = Field(True, description="Write map.png and accuracy histograms.")
