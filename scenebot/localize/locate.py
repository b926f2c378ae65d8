"""Visual localization of one photo against the map (paper section IV.B).

``localize(image, map)``: SIFT features of the photo (pycolmap, as the map's) -> FLANN
KD-tree matching with the ratio test across distinct 3D points -> absolute pose, by the paper's
RANSAC + DLT + RQ + refinement (``method="dlt"``) or pycolmap's P3P LO-RANSAC with refinement
(``method="pycolmap"``). The result is a :class:`PoseEstimate` (camera pose in the map frame,
inlier count, timings) or a typed :class:`LocalizationFailure` - never an exception for a photo
that simply does not localize.
"""

from __future__ import annotations

import enum
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scenebot.geometry import map_mount
from scenebot.localize.config import LocalizeConfig
from scenebot.localize.dlt import position_std_m, ransac_dlt_pose
from scenebot.localize.features import extract_sift, load_gray
from scenebot.localize.index import DescriptorIndex, MapDescriptors
from scenebot.localize.match import Matches, match_to_map


class FailureReason(enum.StrEnum):
    """Why a photo did not localize."""

    TOO_FEW_FEATURES = "too_few_features"
    TOO_FEW_MATCHES = "too_few_matches"
    NO_POSE = "no_pose"
    TOO_FEW_INLIERS = "too_few_inliers"
    IMPLAUSIBLE_POSE = "implausible_pose"
    UNCERTAIN_POSE = "uncertain_pose"
    INCONSISTENT_WITH_ODOMETRY = "inconsistent_with_odometry"
    INCONSISTENT_WITH_COMPASS = "inconsistent_with_compass"
    PREDICTED_UNMATCHABLE = "predicted_unmatchable"  # no photo taken (follow.min_matchable_points)


@dataclass(frozen=True)
class LocalizationFailure:
    """A photo that did not localize (the caller falls back to odometry)."""

    reason: FailureReason
    num_features: int = 0
    num_matches: int = 0
    num_inliers: int = 0
    timings_s: dict = field(default_factory=dict)
    rejected: PoseEstimate | None = None

    @property
    def ok(self) -> bool:
        return False

    def as_record(self) -> dict:
        """The failure as the capture log writes it; a pose that was estimated and then
        judged (``implausible_pose``, ``uncertain_pose``) goes along as ``rejected_pose``
        (centre, heading, predicted error), so that the evaluation can tell how often the
        checks turned away a right fix (:func:`scenebot.evaluate.metrics.localization_accuracy`)."""
        out = {
            "ok": False,
            "reason": str(self.reason),
            "num_features": self.num_features,
            "num_matches": self.num_matches,
            "num_inliers": self.num_inliers,
            "timings_s": self.timings_s,
        }
        if self.rejected is not None:
            r = self.rejected
            out["rejected_pose"] = {
                "center": r.center.tolist(),
                "heading": r.heading,
                "R_cam_from_world": r.R.tolist(),
                "position_std_m": r.position_std_m,
                "rmse_px": r.rmse_px,
            }
        return out


@dataclass(frozen=True)
class PoseEstimate:
    """A camera pose in the map frame.

    Attributes:
        R: (3, 3) rotation cam_from_world (camera axes x right, y down, z forward).
        t: (3,) translation cam_from_world (m).
        focal_px: focal length used/refined (pixels).
        num_features, num_matches, num_inliers: counts along the way.
        rmse_px: reprojection RMSE of the inliers (pixels).
        method: ``"dlt"`` or ``"pycolmap"``.
        timings_s: seconds spent in ``extract``, ``match``, ``pose``, ``total``.
        position_std_m: predicted 1-sigma error of the camera centre in the plane, along its
            worst direction (m; :func:`scenebot.localize.dlt.position_std_m`), or None.
    """

    R: np.ndarray
    t: np.ndarray
    focal_px: float
    num_features: int
    num_matches: int
    num_inliers: int
    rmse_px: float
    method: str
    timings_s: dict = field(default_factory=dict)
    position_std_m: float | None = None

    @property
    def ok(self) -> bool:
        return True

    @property
    def center(self) -> np.ndarray:
        """(3,) camera centre in the map frame (m)."""
        return -self.R.T @ self.t

    @property
    def heading(self) -> float:
        """Heading (rad, counter-clockwise from +x) of the camera's optical axis in the plane."""
        fwd = self.R[2]
        return math.atan2(float(fwd[1]), float(fwd[0]))

    def as_record(self) -> dict:
        c = self.center
        return {
            "ok": True,
            "method": self.method,
            "center": c.tolist(),
            "heading": self.heading,
            "R_cam_from_world": self.R.tolist(),
            "t_cam_from_world": self.t.tolist(),
            "focal_px": self.focal_px,
            "num_features": self.num_features,
            "num_matches": self.num_matches,
            "num_inliers": self.num_inliers,
            "rmse_px": self.rmse_px,
            "position_std_m": self.position_std_m,
            "timings_s": self.timings_s,
        }


class LocalizationMap:
    """What localization needs from a map: descriptors, their index and the camera.

    Args:
        descriptors: the map's point descriptors.
        camera: the map's ``pycolmap.Camera`` (intrinsics of the robot's camera).
        index: a prebuilt index (built from ``descriptors`` if None).
        cfg: localization settings (index parameters).
        mount_pitch_deg: the median pitch of the map's photos (deg; the camera's mount,
            :func:`scenebot.geometry.mount_pitch`): ``localize.camera_pitch_deg: map``.
    """

    def __init__(
        self,
        descriptors: MapDescriptors,
        camera,
        index: DescriptorIndex | None = None,
        cfg: LocalizeConfig | None = None,
        mount_pitch_deg: float = 0.0,
    ):
        cfg = cfg or LocalizeConfig()
        self.descriptors = descriptors
        self.camera = camera
        self.mount_pitch_deg = float(mount_pitch_deg)
        self.index = index or DescriptorIndex(
            descriptors.descriptors, cfg.flann_trees, cfg.flann_checks
        )

    @staticmethod
    def load(
        sfm_dir: Path,
        cfg: LocalizeConfig | None = None,
        cache: bool = True,
        cache_file: Path | None = None,
    ):
        """Load ``sfm_dir`` (COLMAP model + point_descriptors.npz) and its FLANN index.

        Args:
            sfm_dir: the map folder.
            cfg: localization settings.
            cache: cache the index on disk (built once per map).
            cache_file: where; default ``sfm_dir/point_descriptors.flann`` (pass a path
                outside the sfm stage's output folder if that folder must stay untouched).

        Raises:
            FileNotFoundError: the model or the descriptors are missing.
        """
        import pycolmap

        cfg = cfg or LocalizeConfig()
        sfm_dir = Path(sfm_dir)
        desc = MapDescriptors.load(sfm_dir / "point_descriptors.npz")
        cams_file = sfm_dir / "cameras.bin"
        if not cams_file.exists():
            raise FileNotFoundError(f"{cams_file}: missing; run the sfm stage for this round")
        rec = pycolmap.Reconstruction(str(sfm_dir))
        cams = rec.cameras
        if not cams:
            raise ValueError(f"{cams_file}: no camera in the model")
        pitch = math.degrees(map_mount(rec)[1])
        camera = cams[min(cams)]
        if cache and cache_file is None:
            cache_file = sfm_dir / "point_descriptors.flann"
        if not cache:
            cache_file = None
        index = DescriptorIndex.cached(desc, cache_file, cfg.flann_trees, cfg.flann_checks)
        return LocalizationMap(desc, camera, index, cfg, mount_pitch_deg=pitch)


def _undistorted_pinhole(camera, xy: np.ndarray) -> tuple[np.ndarray, float, float, float]:
    """Pixels of an ideal pinhole camera with the map camera's focal length and centre."""
    f = float(camera.mean_focal_length())
    cx, cy = float(camera.principal_point_x), float(camera.principal_point_y)
    if len(xy) == 0:
        return xy, f, cx, cy
    norm = np.asarray(camera.cam_from_img(np.asarray(xy, float)), float)
    return norm * f + np.array([cx, cy]), f, cx, cy


def estimate_pose(
    keypoints: np.ndarray, matches: Matches, camera, cfg: LocalizeConfig
) -> tuple[np.ndarray, np.ndarray, float, int, float, float] | None:
    """Absolute pose from the matches with the configured method.

    Returns:
        (R (3, 3), t (3,), focal_px, num_inliers, rmse_px, position_std_m), or None if no
        pose was found. ``position_std_m``: the predicted planar error of the centre
        (:func:`scenebot.localize.dlt.position_std_m`, image noise = the inliers' RMSE, at
        least ``cfg.min_noise_px``).
    """
    x = keypoints[matches.query_idx]
    X = matches.xyz
    if cfg.method == "pycolmap":
        import pycolmap

        opts = pycolmap.AbsolutePoseEstimationOptions()
        opts.ransac.max_error = cfg.ransac_max_error_px
        opts.ransac.confidence = cfg.ransac_confidence
        opts.ransac.max_num_trials = cfg.ransac_max_iterations
        opts.ransac.random_seed = cfg.seed
        res = pycolmap.estimate_and_refine_absolute_pose(x, X, camera, opts)
        if res is None:
            return None
        m = np.asarray(res["cam_from_world"].matrix())
        R, t = m[:, :3], m[:, 3]
        inl = np.asarray(res["inlier_mask"], bool)
        uv = np.asarray(camera.img_from_cam(X[inl] @ R.T + t), float)
        rmse = float(np.sqrt(((uv[:, :2] - x[inl]) ** 2).sum(axis=1).mean())) if inl.any() else 0.0
        xu, f, cx, cy = _undistorted_pinhole(camera, x[inl])
        std = position_std_m(xu, X[inl], f, cx, cy, R, t, max(rmse, cfg.min_noise_px))
        return R, t, float(camera.mean_focal_length()), int(res["num_inliers"]), rmse, std
    xu, f, cx, cy = _undistorted_pinhole(camera, x)
    pose = ransac_dlt_pose(
        xu,
        X,
        cx,
        cy,
        f_init=f,
        max_error_px=cfg.ransac_max_error_px,
        confidence=cfg.ransac_confidence,
        max_iterations=cfg.ransac_max_iterations,
        refine_focal=cfg.refine_focal,
        seed=cfg.seed,
    )
    if pose is None:
        return None
    m = pose.inliers
    std = position_std_m(xu[m], X[m], pose.focal_px, cx, cy, pose.R, pose.t,
                         max(pose.rmse_px, cfg.min_noise_px))  # fmt: skip
    return pose.R, pose.t, pose.focal_px, int(m.sum()), pose.rmse_px, std


def localize(
    image: str | Path | np.ndarray,
    loc_map: LocalizationMap,
    cfg: LocalizeConfig | None = None,
) -> PoseEstimate | LocalizationFailure:
    """Localize one photo in the map.

    Args:
        image: path of the photo, or an (H, W[, 3]) uint8 array.
        loc_map: the map (see :meth:`LocalizationMap.load`).
        cfg: settings (defaults if None).

    Returns:
        The camera pose with its inlier count, or a typed failure.

    Raises:
        FileNotFoundError: the photo cannot be read.
        ValueError: the photo's size differs from the map camera's.
    """
    cfg = cfg or LocalizeConfig()
    t0 = time.perf_counter()
    gray = load_gray(image)
    cam = loc_map.camera
    if gray.shape != (cam.height, cam.width):
        raise ValueError(
            f"photo is {gray.shape[1]}x{gray.shape[0]} but the map camera is "
            f"{cam.width}x{cam.height}; localize photos of the camera that built the map"
        )
    kps, desc = extract_sift(
        gray, cfg.sift_first_octave, cfg.sift_max_features, cfg.sift_num_threads
    )
    t1 = time.perf_counter()
    timings = {"extract": t1 - t0}
    if len(kps) < cfg.min_matches:
        timings["total"] = t1 - t0
        return LocalizationFailure(FailureReason.TOO_FEW_FEATURES, len(kps), 0, 0, timings)
    matches = match_to_map(desc, loc_map.index, loc_map.descriptors, cfg.knn, cfg.ratio)
    t2 = time.perf_counter()
    timings["match"] = t2 - t1
    if len(matches) < cfg.min_matches:
        timings["total"] = t2 - t0
        return LocalizationFailure(
            FailureReason.TOO_FEW_MATCHES, len(kps), len(matches), 0, timings
        )
    pose = estimate_pose(kps, matches, cam, cfg)
    t3 = time.perf_counter()
    timings["pose"] = t3 - t2
    timings["total"] = t3 - t0
    if pose is None:
        return LocalizationFailure(FailureReason.NO_POSE, len(kps), len(matches), 0, timings)
    R, t, f, n_inl, rmse, std = pose
    if n_inl < cfg.min_inliers:
        return LocalizationFailure(
            FailureReason.TOO_FEW_INLIERS, len(kps), len(matches), n_inl, timings
        )
    est = PoseEstimate(R, t, f, len(kps), len(matches), n_inl, rmse, cfg.method, timings, std)
    if not plausible_robot_camera(est, cfg, loc_map.mount_pitch_deg):
        return LocalizationFailure(
            FailureReason.IMPLAUSIBLE_POSE, len(kps), len(matches), n_inl, timings, est
        )
    if cfg.max_position_std_m is not None and not std <= cfg.max_position_std_m:
        return LocalizationFailure(
            FailureReason.UNCERTAIN_POSE, len(kps), len(matches), n_inl, timings, est
        )
    return est


def plausible_robot_camera(
    est: PoseEstimate, cfg: LocalizeConfig, mount_pitch_deg: float = 0.0
) -> bool:
    """Whether a pose fits a camera on a planar robot: centre near the camera plane, optical
    axis at the configured pitch (``map``: ``mount_pitch_deg``, the map's), no roll (see the
    ``LocalizeConfig`` fields)."""
    if (
        cfg.camera_plane_z_m is not None
        and abs(float(est.center[2]) - cfg.camera_plane_z_m) > cfg.max_height_dev_m
    ):
        return False
    if cfg.camera_pitch_deg is not None:
        # rows of R: camera x (right), y (down), z (forward) axes in the map frame (z up)
        pitch = math.degrees(math.asin(float(np.clip(est.R[2, 2], -1.0, 1.0))))
        roll = math.degrees(math.asin(float(np.clip(est.R[0, 2], -1.0, 1.0))))
        want = mount_pitch_deg if cfg.camera_pitch_deg == "map" else cfg.camera_pitch_deg
        if abs(pitch - want) > cfg.max_tilt_deg or abs(roll) > cfg.max_tilt_deg:
            return False
    return True


def make_localizer(
    sfm_dir: Path, cfg: LocalizeConfig | None = None, cache_file: Path | None = None
):
    """A ``photo path -> PoseEstimate | LocalizationFailure`` callable for a map folder.

    The map and its FLANN index are loaded once (the index is cached at ``cache_file``,
    default ``sfm_dir/point_descriptors.flann``); this is the ``localizer`` argument of
    :class:`scenebot.capture.follow.PathFollower`.
    """
    cfg = cfg or LocalizeConfig()
    lmap = LocalizationMap.load(sfm_dir, cfg, cache_file=cache_file)

    def localizer(image: str | Path | np.ndarray) -> PoseEstimate | LocalizationFailure:
        return localize(image, lmap, cfg)

    localizer.map = lmap  # type: ignore[attr-defined]
    return localizer
