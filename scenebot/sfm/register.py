"""An adaptive round's fast path: register its new photos into the previous round's map.

Round r-1's model is already in the robot frame and its photos' poses are what the robot
and the later stages used. The new photos are registered one by one into it with COLMAP's
incremental mapper (absolute pose by RANSAC from each photo's matches to the map's points,
triangulation of its new tracks, local bundle adjustment of it and its most connected
neighbours); the previous photos' poses and the camera intrinsics stay fixed throughout.

The robot's own estimate of where it took a photo (its visual localization fix, or the last
fix carried by odometry) is the second initial guess: the pose is also refined from there
on all the photo's matches to map points, and whichever of the two poses explains more of
them within ``sfm.refine_max_error_px`` is kept. Far walls seen at one depth let RANSAC's
12 px inlier threshold settle on a pose turned by a few degrees and shifted by decimetres
(office round 6: two photos 29 and 42 cm off, 1.0-1.9 px median error; refined from the
robot's estimate 1.3 cm off, 0.3-0.5 px).

A pose that contradicts the robot's estimate (camera centre farther than
``sfm.max_estimate_deviation_m``, or heading farther than ``sfm.max_compass_deviation_deg``:
the tolerances by which the stage leaves such photos out of the map anyway) is estimated again
from the photo's matches that the estimate allows (:func:`gate_correspondences`): repeating
wallpaper and parquet give a photo matches to the pattern's other copies, and RANSAC can
settle on a copy metres away (the flat, round 3: 20 of 26 new photos registered, 15 of them
1-3 m off). Is the gated pose within the tolerances, it replaces the first; otherwise the photo
is taken out of the map again before its points are triangulated.

Then the new photos get the robust refinement the whole map gets on the slow path (drop
observations beyond ``sfm.refine_max_error_px``, bundle adjustment with a Cauchy loss), but
only over the new photos and the points they see. No global bundle adjustment runs here:
:func:`global_refinement_checks` says when the map needs one.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pycolmap

from scenebot.geometry import look_rotation, map_mount
from scenebot.sfm.config import SfmConfig
from scenebot.sfm.features import database_cache
from scenebot.sfm.mapping import (
    MappingResult,
    ObservationTable,
    _ba_options,
    dropped_photos,
    filter_observations,
    mapping_options,
)
from scenebot.sfm.photos import Photo

log = logging.getLogger(__name__)


@dataclass
class Registration:
    """The previous map with the new photos registered into it.

    Attributes:
        reconstruction: the model (the previous model's frame).
        new_ids: image ids of the photos registered now.
        previous_ids: image ids of the previous model's photos (poses held).
        stats: counts and seconds per step (report.json ``refinement``).
        rejected: photo name -> why it was taken out again (its pose against the robot's
            estimate).
        unreachable: photo name -> how many of the map's points its features match, for
            the photos left unregistered with fewer than the mapper asks of a registration
            (``abs_pose_min_num_inliers``).
    """

    reconstruction: pycolmap.Reconstruction
    new_ids: list[int]
    previous_ids: set[int]
    stats: dict = field(default_factory=dict)
    rejected: dict[str, str] = field(default_factory=dict)
    unreachable: dict[str, int] = field(default_factory=dict)


def map_new_photos(
    db_path: Path,
    image_root: Path,
    photos: list[Photo],
    cfg: SfmConfig,
    previous: pycolmap.Reconstruction,
    camera_offset_m: tuple[float, float] | None,
    shots: list[pycolmap.Rigid3d] | None = None,
) -> tuple[MappingResult | None, pycolmap.Reconstruction]:
    """The fast path: the new photos registered into ``previous`` (:func:`register_new_photos`,
    the robot's estimates as second initial guesses, :func:`camera_priors`) and refined
    (:func:`refine_new_photos`); mode ``registered``.

    Args:
        camera_offset_m: the camera centre in the robot frame (forward, left) (m), as the
            previous map's alignment found it; None: at the robot's position.
        shots: a guided round's shots (:func:`shot_poses`, the previous map's frame): where
            a person's new photos were meant to be taken.

    Returns:
        The mapping result, or None (logged) when fewer than ``cfg.min_registered_share``
        of the new photos registered: the caller maps the slow way.
    """
    t0 = time.perf_counter()
    names = [p.name for p in photos]
    height, pitch = map_mount(previous)
    priors = camera_priors(photos, camera_offset_m, cfg.camera_yaw_deg, height, pitch)
    reg = register_new_photos(db_path, image_root, names, cfg, previous, priors, shots)
    n_new = len(names) - len(reg.previous_ids)
    # a photo taken out against the robot's estimate is judged, not missed: the incremental
    # mapper would only register it where the estimate says it was not (and the stage would
    # leave it out again, sfm.max_estimate_deviation_m); one whose features match fewer map
    # points than any registration needs is out of every mapper's reach (the flat's rounds 1
    # and 3: the mapper, run after the fast path, added no photo to it)
    judged = len(reg.new_ids) + len(reg.rejected) + len(reg.unreachable)
    if judged < cfg.min_registered_share * n_new:
        log.warning(
            "%d of %d new photos registered into the previous map, %d taken out against the "
            "robot's estimate, %d match too few map points to register (< "
            "sfm.min_registered_share = %g): continuing with the incremental mapper",
            len(reg.new_ids),
            n_new,
            len(reg.rejected),
            len(reg.unreachable),
            cfg.min_registered_share,
        )
        return None, reg.reconstruction
    refinement = refine_new_photos(reg, cfg) | reg.stats
    refinement["fixed_previous_photos"] = len(reg.previous_ids)
    rec = reg.reconstruction
    log.info(
        "registered %d of %d new photos into the previous map in %.1f s",
        len(reg.new_ids),
        n_new,
        time.perf_counter() - t0,
    )
    result = MappingResult(
        rec,
        "registered",
        1,
        dropped_photos(db_path, names, [rec], cfg) | reg.rejected,
        time.perf_counter() - t0,
        refinement,
        new_ids=reg.new_ids,
    )
    result.overruled = len(reg.rejected)
    return result, rec


def camera_xy(
    pose: tuple[float, float, float], camera_offset_m: tuple[float, float] | None
) -> np.ndarray:
    """The camera centre (x, y) (m) of the robot at ``pose`` (x, y, theta) whose camera sits
    ``camera_offset_m`` (forward, left) (m; None: on the rotation axis) from its axis."""
    fwd, left = (0.0, 0.0) if camera_offset_m is None else map(float, camera_offset_m)
    x, y, th = pose
    c, s = math.cos(th), math.sin(th)
    return np.array([x + fwd * c - left * s, y + fwd * s + left * c])


def camera_priors(
    photos: list[Photo],
    camera_offset_m: tuple[float, float] | None,
    camera_yaw_deg: float,
    height_m: float,
    pitch_rad: float = 0.0,
) -> dict[str, pycolmap.Rigid3d]:
    """Photo name -> camera pose (cam_from_world, robot frame) where the robot's own
    estimate (``localization``) puts it: a camera at the robot's heading plus
    ``camera_yaw_deg``, tilted up by its mount's ``pitch_rad`` (the map's,
    :func:`~scenebot.geometry.mount_pitch`), its centre ``camera_offset_m`` (forward, left)
    from the robot's position at height ``height_m``. Photos without an estimate are left
    out."""
    out: dict[str, pycolmap.Rigid3d] = {}
    for p in photos:
        if p.localization is None:
            continue
        centre = np.r_[camera_xy(p.localization, camera_offset_m), height_m]
        rot = look_rotation(p.localization[2] + math.radians(camera_yaw_deg), pitch_rad)
        out[p.name] = pycolmap.Rigid3d(pycolmap.Rotation3d(rot), -rot @ centre)
    return out


def shot_poses(goals: list[dict]) -> list[pycolmap.Rigid3d]:
    """cam_from_world of each shot of a guide (goals.json ``goals``: camera centre x, y, z,
    heading ``theta``, tilt ``pitch``; no roll), in the frame of the map they were planned
    on."""
    out = []
    for g in goals:
        rot = look_rotation(float(g["theta"]), float(g.get("pitch", 0.0)))
        centre = np.array([g["x"], g["y"], g.get("z", 0.0)], float)
        out.append(pycolmap.Rigid3d(pycolmap.Rotation3d(rot), -rot @ centre))
    return out


def register_new_photos(
    db_path: Path,
    image_root: Path,
    names: list[str],
    cfg: SfmConfig,
    previous: pycolmap.Reconstruction,
    priors: dict[str, pycolmap.Rigid3d],
    shots: list[pycolmap.Rigid3d] | None = None,
) -> Registration:
    """Register the photos of ``names`` missing from ``previous`` into a copy of it.

    Args:
        db_path: the scene database (features and matches of all ``names``).
        image_root: folder the names are relative to (for point colours).
        names: the photo set; photos of ``previous`` outside it are taken out.
        cfg: sfm settings (pose and triangulation thresholds of the incremental mapper).
        previous: round r-1's model, image ids as in the database.
        priors: photo name -> the robot's estimate of its camera pose (:func:`camera_priors`).
        shots: the poses a person's photos (no estimate) were meant to be taken at (a
            guided round's shots, :func:`shot_poses`), checked within
            ``cfg.person_shot_distance_m`` / ``person_shot_heading_deg``.

    Returns:
        The registration (photos that did not register are simply not in the model).
    """
    t0 = time.perf_counter()
    rec = pycolmap.Reconstruction(previous)
    keep = set(names)
    for iid in list(rec.reg_image_ids()):
        if rec.image(iid).name not in keep:
            rec.deregister_frame(rec.image(iid).frame_id)
    previous_ids = set(rec.reg_image_ids())
    cache = database_cache(db_path, keep, cfg.min_num_matches)
    opts = mapping_options(cfg, names, continuing=True, fix_focal=True)
    mopts = opts.get_mapper()
    mopts.fix_existing_frames = True
    mopts.constant_cameras = set(rec.cameras.keys())
    mopts.abs_pose_refine_extra_params = False
    mapper = pycolmap.IncrementalMapper(cache)
    mapper.begin_reconstruction(rec)
    guess = _PriorGuess(
        mapper,
        cache.correspondence_graph,
        priors,
        cfg.refine_max_error_px,
        Tolerance(cfg.max_estimate_deviation_m, cfg.max_compass_deviation_deg),
        mopts.abs_pose_min_num_inliers,
        shots,
        Tolerance(cfg.person_shot_distance_m, cfg.person_shot_heading_deg),
    )
    new_ids = _register_loop(mapper, opts, mopts, guess)
    unreachable = _unreachable(
        rec, cache.correspondence_graph, names, previous_ids, new_ids, guess.rejected,
        mopts.abs_pose_min_num_inliers,
    )  # fmt: skip
    mapper.end_reconstruction(False)
    for iid in new_ids:
        rec.extract_colors_for_image(iid, str(image_root))
    stats = {
        "registered_now": len(new_ids),
        "poses_from_robot_estimate": guess.taken,
        "poses_from_gated_matches": guess.gated,
        "rejected_against_robot_estimate": len(guess.rejected),
        "too_few_map_matches": len(unreachable),
        "register_seconds": time.perf_counter() - t0,
    }
    if guess.shots:
        stats["shot_checks"] = guess.shot_checks
    return Registration(rec, new_ids, previous_ids, stats, dict(guess.rejected_names), unreachable)


def _unreachable(
    rec: pycolmap.Reconstruction,
    graph: pycolmap.CorrespondenceGraph,
    names: list[str],
    previous_ids: set[int],
    new_ids: list[int],
    rejected: set[int],
    min_inliers: int,
) -> dict[str, int]:
    """The photos of ``names`` left unregistered (neither in the map nor taken out against
    the robot's estimate) whose 2D points match fewer than ``min_inliers`` of the map's 3D
    points: no pose solver, the incremental mapper's included, can register them against
    this map (its own bar for a registration); name -> matched map points."""
    done = previous_ids | set(new_ids) | set(rejected)
    ids = {im.name: iid for iid, im in rec.images.items()}
    out = {}
    for name in names:
        iid = ids.get(name)
        if iid in done:
            continue
        # a photo the mapper did not even load has no verified pair: no match at all
        n = 0 if iid is None else len(map_correspondences(rec, graph, iid)[0])
        if n < min_inliers:
            out[name] = n
    return out


@dataclass(frozen=True)
class Tolerance:
    """How far a registered pose may lie from the robot's estimate: camera centre (m,
    horizontal) and heading (deg); 0 or less: not checked."""

    position_m: float
    heading_deg: float

    def agrees(self, pose: pycolmap.Rigid3d, prior: pycolmap.Rigid3d) -> bool:
        """Whether ``pose`` lies within the tolerances of ``prior`` (both cam_from_world)."""
        if self.position_m > 0:
            d = np.linalg.norm((camera_centre(pose) - camera_centre(prior))[:2])
            if d > self.position_m:
                return False
        if self.heading_deg > 0:
            dh = abs(math.degrees(_wrap(_heading(pose) - _heading(prior))))
            if dh > self.heading_deg:
                return False
        return True


def camera_centre(pose: pycolmap.Rigid3d) -> np.ndarray:
    return -pose.rotation.matrix().T @ np.asarray(pose.translation)


def _heading(pose: pycolmap.Rigid3d) -> float:
    view = pose.rotation.matrix()[2]
    return math.atan2(view[1], view[0])


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


class _PriorGuess:
    """The robot's estimate of a just registered photo's pose: a second initial guess, and a
    check (:meth:`check`).

    Attributes:
        taken: how many photos kept the pose refined from the robot's estimate.
        gated: how many photos took the pose estimated from their gated matches.
        rejected: image ids taken out again (no pose within the tolerances).
        rejected_names: their names -> why.
        shots, shot_tolerance: a guided round's shots, for the photos without an estimate
            (:meth:`_check_against_shots`); shot_checks: its decision per photo.
    """

    def __init__(
        self,
        mapper: pycolmap.IncrementalMapper,
        graph: pycolmap.CorrespondenceGraph,
        priors: dict[str, pycolmap.Rigid3d],
        max_error_px: float,
        tolerance: Tolerance | None = None,
        min_inliers: int = 30,
        shots: list[pycolmap.Rigid3d] | None = None,
        shot_tolerance: Tolerance | None = None,
    ) -> None:
        self.mapper, self.graph, self.priors = mapper, graph, priors
        self.max_error_px = max_error_px
        self.tolerance = tolerance or Tolerance(0.0, 0.0)
        self.min_inliers = min_inliers
        self.taken = 0
        self.gated = 0
        self.rejected: set[int] = set()
        self.rejected_names: dict[str, str] = {}
        self.shots = list(shots or [])  # a person's photos: where they were meant to be
        self.shot_tolerance = shot_tolerance or Tolerance(0.0, 0.0)
        self.shot_checks: dict[str, dict] = {}

    def check(self, iid: int, drop_error_px: float, max_error_px: float) -> bool:
        """Hold image ``iid``'s new pose against the robot's estimate: within the
        tolerances, try the estimate as a second initial guess (:meth:`try_pose`); beyond
        them, estimate the pose again from the matches the estimate allows (RANSAC at
        ``max_error_px``, :func:`gate_correspondences`) and take it when it lies within the
        tolerances, else take the photo out of the map. Returns whether it stays."""
        rec = self.mapper.reconstruction
        im = rec.image(iid)
        prior = self.priors.get(im.name)
        if prior is None and self.shots and self.shot_tolerance.position_m > 0:
            self._check_against_shots(iid, drop_error_px, max_error_px)
            return True
        if prior is None or self.tolerance.agrees(im.cam_from_world(), prior):
            self.try_pose(iid, drop_error_px)
            return True
        pose = self._gated_pose(iid, prior, max_error_px)
        if pose is not None:
            self._set_pose(iid, pose, drop_error_px)
            self.gated += 1
            return True
        d = float(np.linalg.norm((camera_centre(im.cam_from_world()) - camera_centre(prior))[:2]))
        self.mapper.observation_manager.deregister_frame(im.frame_id)
        self.rejected.add(iid)
        self.rejected_names[im.name] = (
            f"registered {d:.2f} m from the robot's own estimate, and its matches that the "
            "estimate allows give no pose within sfm.max_estimate_deviation_m / "
            "sfm.max_compass_deviation_deg"
        )
        return False

    def _check_against_shots(self, iid: int, drop_error_px: float, max_error_px: float) -> None:
        """A person's photo (no robot estimate) against the guide's shots: a pose within
        ``shot_tolerance`` of a shot stays; otherwise the pose near a shot that its gated
        matches give (:func:`pose_near_estimate` from each shot), the one with the most
        inliers, replaces it; with none, the photo keeps its own pose (taken away from
        the guide). Each decision goes to :attr:`shot_checks` (report.json)."""
        rec = self.mapper.reconstruction
        im = rec.image(iid)
        pose = im.cam_from_world()
        dist = [float(np.linalg.norm(camera_centre(pose) - camera_centre(s))) for s in self.shots]
        near = int(np.argmin(dist))
        row: dict = {"nearest_shot": near, "distance": dist[near], "map_points": im.num_points3D}
        if any(self.shot_tolerance.agrees(pose, s) for s in self.shots):
            self.shot_checks[im.name] = row | {"pose": "registered, near a shot"}
            return
        _, xy, xyz = map_correspondences(rec, self.graph, iid, every=True)
        best = None
        for k, shot in enumerate(self.shots):
            found = pose_near_estimate(
                im.camera, shot, xy, xyz, self.shot_tolerance, max_error_px, self.min_inliers,
                with_inliers=True,
            )  # fmt: skip
            if found is not None and (best is None or found[1] > best[2]):
                best = (k, found[0], found[1])
        if best is None:
            self.shot_checks[im.name] = row | {
                "pose": "registered, near no shot (no pose near a shot from its matches)"
            }
            return
        k, shot_pose, inliers = best
        moved = float(np.linalg.norm(camera_centre(shot_pose) - camera_centre(pose)))
        self._set_pose(iid, shot_pose, drop_error_px)
        self.gated += 1
        self.shot_checks[im.name] = row | {
            "pose": f"from its matches near shot {k}",
            "shot": k,
            "inliers": inliers,
            "moved": moved,
        }

    def _gated_pose(
        self, iid: int, prior: pycolmap.Rigid3d, max_error_px: float
    ) -> pycolmap.Rigid3d | None:
        rec = self.mapper.reconstruction
        im = rec.image(iid)
        _, xy, xyz = map_correspondences(rec, self.graph, iid, every=True)
        return pose_near_estimate(
            im.camera, prior, xy, xyz, self.tolerance, max_error_px, self.min_inliers
        )

    def _set_pose(self, iid: int, pose: pycolmap.Rigid3d, drop_error_px: float) -> None:
        """Give image ``iid`` ``pose`` and drop its observations it puts beyond
        ``drop_error_px`` (triangulation then continues its tracks from the new pose)."""
        rec = self.mapper.reconstruction
        rec.frame(rec.image(iid).frame_id).rig_from_world = pose
        table = ObservationTable(rec, [iid])
        for k in table.point2D_idx[~(table.errors(rec) <= drop_error_px)]:
            self.mapper.observation_manager.delete_observation(iid, int(k))

    def try_pose(self, iid: int, drop_error_px: float) -> bool:
        """Refine the pose of image ``iid`` from its prior on all its matches to map
        points (Cauchy loss); keep it when it explains more of them within
        ``max_error_px`` than the registered pose, dropping the observations it puts
        beyond ``drop_error_px``. Returns whether the pose was replaced."""
        rec = self.mapper.reconstruction
        im = rec.image(iid)
        prior = self.priors.get(im.name)
        if prior is None:
            return False
        idx, xy, xyz = map_correspondences(rec, self.graph, iid)
        if len(idx) < 6:
            return False
        refined = pycolmap.refine_absolute_pose(
            prior, xy, xyz, np.ones(len(idx), bool), im.camera,
            pycolmap.AbsolutePoseRefinementOptions(),
        )  # fmt: skip
        if refined is None:
            return False
        pose = refined["cam_from_world"]
        errors = [_errors(im.camera, p, xy, xyz) for p in (im.cam_from_world(), pose)]
        if np.sum(errors[1] <= self.max_error_px) <= np.sum(errors[0] <= self.max_error_px):
            return False
        self._set_pose(iid, pose, drop_error_px)
        self.taken += 1
        return True


def pose_near_estimate(
    camera: pycolmap.Camera,
    prior: pycolmap.Rigid3d,
    xy: np.ndarray,
    xyz: np.ndarray,
    tolerance: Tolerance,
    max_error_px: float,
    min_inliers: int,
    attempts: int = 3,
    with_inliers: bool = False,
):
    """A pose within ``tolerance`` of the robot's estimate from the 2D-3D matches it allows
    (:func:`gate_correspondences`): RANSAC (``max_error_px``), and while its pose lies
    outside the tolerances, again without that pose's inliers (a repeated pattern gives
    several consistent poses, one per copy; the estimate says which copy), ``attempts``
    times at most. None when no pose with ``min_inliers`` inliers lies within them; with
    ``with_inliers``, (pose, inlier count)."""
    keep = gate_correspondences(camera, prior, xy, xyz, tolerance.position_m, tolerance.heading_deg)
    xy, xyz = np.asarray(xy)[keep], np.asarray(xyz)[keep]
    est = pycolmap.AbsolutePoseEstimationOptions()
    est.ransac.max_error = max_error_px
    est.ransac.random_seed = 0
    for _ in range(attempts):
        if len(xy) < min_inliers:
            return None
        ans = pycolmap.estimate_and_refine_absolute_pose(xy, xyz, camera, est)
        if ans is None or ans["num_inliers"] < min_inliers:
            return None
        if tolerance.agrees(ans["cam_from_world"], prior):
            pose = ans["cam_from_world"]
            return (pose, int(ans["num_inliers"])) if with_inliers else pose
        out = ~np.asarray(ans["inlier_mask"], bool)
        xy, xyz = xy[out], xyz[out]
    return None


def gate_correspondences(
    camera: pycolmap.Camera,
    prior: pycolmap.Rigid3d,
    xy: np.ndarray,
    xyz: np.ndarray,
    position_m: float,
    angle_deg: float,
) -> np.ndarray:
    """Which 2D-3D matches a camera near ``prior`` could have made: the 3D point lies within
    ``position_m + depth * sin(angle_deg)`` of the prior's ray through the pixel (a camera
    centre up to ``position_m`` away, its orientation up to ``angle_deg`` off), in front of
    the camera. A copy of a repeated pattern elsewhere in the room fails this.

    Args:
        camera: the photo's camera (intrinsics).
        prior: the robot's estimate (cam_from_world).
        xy: (M, 2) pixel positions; xyz: (M, 3) their 3D points (map frame).
        position_m, angle_deg: the tolerances (0 or less: 0).

    Returns:
        (M,) bool.
    """
    if not len(xy):
        return np.zeros(0, bool)
    rays = camera.cam_from_img(np.asarray(xy, np.float64))
    rays = np.c_[rays, np.ones(len(rays))]
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    p = prior * np.asarray(xyz, np.float64)  # points in the prior camera's frame
    along = np.sum(p * rays, axis=1)
    off = np.linalg.norm(p - along[:, None] * rays, axis=1)
    depth = np.linalg.norm(p, axis=1)
    allowed = max(position_m, 0.0) + depth * math.sin(math.radians(max(angle_deg, 0.0)))
    return (along > 0) & (off <= allowed)


def map_correspondences(
    rec: pycolmap.Reconstruction,
    graph: pycolmap.CorrespondenceGraph,
    iid: int,
    every: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The matches of image ``iid``'s points to 3D points of ``rec`` (through the
    correspondences with registered images' observations): point2D indices (M,), their
    pixel positions (M, 2) and the 3D points (M, 3); one per 2D point (its first), or with
    ``every`` each distinct 3D point a 2D point matches."""
    im = rec.image(iid)
    idx, xy, xyz = [], [], []
    for k in range(im.num_points2D()):
        seen: set[int] = set()
        for c in graph.extract_correspondences(iid, k):
            other = rec.image(c.image_id) if rec.exists_image(c.image_id) else None
            if other is None or not other.has_pose:
                continue
            p2 = other.point2D(c.point2D_idx)
            if p2.has_point3D() and p2.point3D_id not in seen:
                seen.add(p2.point3D_id)
                idx.append(k)
                xy.append(im.point2D(k).xy)
                xyz.append(rec.point3D(p2.point3D_id).xyz)
                if not every:
                    break
    return np.array(idx, np.int64), np.array(xy).reshape(-1, 2), np.array(xyz).reshape(-1, 3)


def _errors(
    camera: pycolmap.Camera, pose: pycolmap.Rigid3d, xy: np.ndarray, xyz: np.ndarray
) -> np.ndarray:
    """Reprojection errors (px) of ``xyz`` against ``xy`` at ``pose`` (inf behind it)."""
    cam_pts = pose * xyz
    err = np.linalg.norm(camera.img_from_cam(cam_pts, check_cheirality=False) - xy, axis=1)
    err[cam_pts[:, 2] <= 0] = np.inf
    return err


def _register_loop(
    mapper: pycolmap.IncrementalMapper,
    opts: pycolmap.IncrementalPipelineOptions,
    mopts: pycolmap.IncrementalMapperOptions,
    guess: _PriorGuess,
) -> list[int]:
    """Register the next best image while one registers (COLMAP's order: most visible map
    points first; structure-less resectioning when none registers from map points), try
    the robot's estimate as a second initial pose and check the pose against it
    (:class:`_PriorGuess`), triangulate it and adjust it locally. Returns the ids
    registered, in order (not those taken out again by the check)."""
    tri = opts.get_triangulation()
    local_ba = opts.get_local_bundle_adjustment()
    local_ba.refine_focal_length = False
    local_ba.refine_extra_params = False
    local_ba.refine_principal_point = False
    new_ids: list[int] = []
    while True:
        iid = _register_next(
            mapper, mopts, opts.structure_less_registration_fallback, guess.rejected
        )
        if iid is None:
            return new_ids
        if not guess.check(iid, mopts.filter_max_reproj_error, mopts.abs_pose_max_error):
            continue
        new_ids.append(iid)
        mapper.triangulate_image(tri, iid)
        mapper.iterative_local_refinement(
            opts.ba_local_max_refinements,
            opts.ba_local_max_refinement_change,
            mopts,
            local_ba,
            tri,
            iid,
        )


def _register_next(
    mapper: pycolmap.IncrementalMapper,
    mopts: pycolmap.IncrementalMapperOptions,
    structure_less: bool,
    skip: set[int] = frozenset(),
) -> int | None:
    """Register the first candidate (not in ``skip``) that registers; its id, or None when
    none does."""
    for iid in mapper.find_next_images(mopts, False):
        if iid not in skip and mapper.register_next_image(mopts, iid):
            return iid
    if structure_less:
        for iid in mapper.find_next_images(mopts, True):
            if iid not in skip and mapper.register_next_structure_less_image(mopts, iid):
                return iid
    return None


def refine_new_photos(reg: Registration, cfg: SfmConfig) -> dict:
    """The robust refinement of the new photos: ``cfg.refine_iterations`` times, drop the
    observations of their points beyond ``cfg.refine_max_error_px``, then bundle-adjust
    their poses and points with a Cauchy loss (1 px); the previous photos observe those
    points with their poses held, the intrinsics stay fixed. Filters once more at the end.

    Returns:
        Stats: observations removed, reprojection error (px) of the whole model before and
        after, seconds.
    """
    t0 = time.perf_counter()
    rec = reg.reconstruction
    ids = [i for i in reg.new_ids if rec.exists_image(i) and rec.image(i).has_pose]
    before = rec.compute_mean_reprojection_error()
    removed = 0
    opts = _ba_options(
        cfg.num_threads, refine_focal_length=False, refine_extra_params=False, cauchy_px=1.0
    )
    opts.ceres.solver_options.function_tolerance = cfg.register_ba_function_tolerance
    points = points_of(rec, ids)
    table = ObservationTable(rec, images_of(rec, points), points)
    for _ in range(cfg.refine_iterations if ids else 0):
        removed += filter_observations(rec, cfg.refine_max_error_px, table, points)
        config = pycolmap.BundleAdjustmentConfig()
        for iid in ids:
            config.add_image(iid)
        for pid in points:  # with every observation: the previous photos hold them
            if rec.exists_point3D(pid):
                config.add_variable_point(pid)
        pycolmap.create_default_bundle_adjuster(opts, config, rec).solve()
    if ids:
        removed += filter_observations(rec, cfg.refine_max_error_px, table, points)
    return {
        "observations_removed": removed,
        "reprojection_error_before_px": before,
        "reprojection_error_after_px": rec.compute_mean_reprojection_error(),
        "residual_ratio": residual_ratio(rec, table, ids),
        "seconds": time.perf_counter() - t0,
    }


def points_of(rec: pycolmap.Reconstruction, ids: list[int]) -> set[int]:
    """The 3D points observed by images ``ids``."""
    out: set[int] = set()
    for iid in ids:
        out.update(p.point3D_id for p in rec.image(iid).get_observation_points2D())
    return out


def images_of(rec: pycolmap.Reconstruction, point_ids: set[int]) -> set[int]:
    """The images observing the 3D points ``point_ids``."""
    return {el.image_id for pid in point_ids for el in rec.point3D(pid).track.elements}


def residual_ratio(
    rec: pycolmap.Reconstruction, table: ObservationTable, new_ids: list[int]
) -> float | None:
    """Median reprojection error of the new photos' observations in ``table`` over that of
    the other photos' observations of the same points (None without observations on
    either side, or none of the latter above zero)."""
    err = table.errors(rec)
    is_new = np.isin(table.image_ids, np.asarray(new_ids, np.int64))
    e_new, e_old = err[is_new], err[~is_new]
    if not len(e_new) or not len(e_old) or not np.median(e_old) > 0:
        return None
    return float(np.median(e_new) / np.median(e_old))


def fix_offsets(
    rec: pycolmap.Reconstruction,
    photos: list[Photo],
    new_names: set[str],
    camera_offset_m: tuple[float, float] | None,
) -> dict[str, float]:
    """Name -> horizontal distance (m) between where a new photo registered (``rec`` in the
    robot frame) and where the robot's own visual localization fix of that photo put the
    camera (its pose plus the camera offset (forward, left) in the robot frame)."""
    by_name = {rec.image(i).name: i for i in rec.reg_image_ids()}
    out: dict[str, float] = {}
    for p in photos:
        if p.name not in new_names or p.name not in by_name or not p.localization_fix:
            continue
        centre = rec.image(by_name[p.name]).projection_center()[:2]
        out[p.name] = float(np.linalg.norm(centre - camera_xy(p.localization, camera_offset_m)))
    return out


def global_refinement_checks(
    rec: pycolmap.Reconstruction,
    new_ids: list[int],
    ratio: float | None,
    photos: list[Photo],
    camera_offset_m: tuple[float, float] | None,
    cfg: SfmConfig,
) -> dict:
    """Whether the map needs the global refinement after the fast path (``rec`` in the
    robot frame): the new photos' median reprojection error beyond
    ``cfg.max_residual_ratio`` times the previous photos' on the same points (``ratio``,
    :func:`residual_ratio`), or their median distance from their own visual localization
    fixes (3 fixes at least) beyond ``cfg.max_fix_offset_m``.

    Returns:
        report.json's ``global_refinement``: ``run`` (bool), ``reasons`` and the figures.
    """
    new_names = {rec.image(i).name for i in new_ids if rec.exists_image(i)}
    offsets = fix_offsets(rec, photos, new_names, camera_offset_m)
    median_offset = float(np.median(list(offsets.values()))) if len(offsets) >= 3 else None
    reasons = []
    if ratio is not None and ratio > cfg.max_residual_ratio:
        reasons.append(
            f"the new photos' median reprojection error is {ratio:.2f} x the previous "
            f"photos' on the same points (> sfm.max_residual_ratio = "
            f"{cfg.max_residual_ratio})"
        )
    if 0 < cfg.max_fix_offset_m < (median_offset or 0.0):
        reasons.append(
            f"the new photos registered {100 * median_offset:.1f} cm from their "
            f"localization fixes in the median (> sfm.max_fix_offset_m = "
            f"{cfg.max_fix_offset_m} m)"
        )
    return {
        "run": bool(reasons),
        "reasons": reasons,
        "residual_ratio": ratio,
        "fix_offset_median_m": median_offset,
        "photos_with_fix": len(offsets),
    }
