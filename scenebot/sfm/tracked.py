"""A person's photos mapped from the camera's own tracked motion.

A phone tracks its own motion (visual-inertial odometry, as ARKit and ARCore give it): each
photo's camera pose in its tracking session's frame, level, metric, drifting by 1-3% of the
distance walked (the capture log's ``motion``, :class:`~scenebot.sfm.photos.Motion`). The
incremental mapper ignores it and builds the map from the matches alone, and on repeating
texture the matches fold the map: a wallpaper matched one motif along the same wall gives a
pair whose rotation is right and whose translation points elsewhere, and a match shifted one
motif along the epipolar line agrees with the pair's true geometry while it triangulates a
point at the wrong depth. Measured on the flat's 178-photo walk through every room (the
simulator's truth; the pairs checked against the orientation): 629 of 2,367 verified pairs
wrong, 24 of the pairs with 100 matches or more still mostly wrong after the motion's pair
check (:mod:`scenebot.sfm.orientation`), and the incremental mapper placed every photo
0.8-1.3 m off within its own room (with the tracked positions as priors in its bundle
adjustments too: 0.7-1.1 m).

:func:`map_from_motion` starts from the tracked poses instead: every photo of the session
placed where its phone says it was, the verified matches triangulated between them, bundle
adjustment with a position prior at the tracked centre (``sfm.motion_prior_std_m``), the
observations beyond the reprojection bound dropped, triangulated again; until the poses
settle. A wrong match cannot move a pose far from where the phone was, and its point, seen
from a third photo where no copy lies, leaves the map. The same walk: every photo within
16 cm, the median 0.3 cm after a similarity fit (tracking drifting 1% of the distance; 2%:
median 1.1 cm, 2 photos beyond 25 cm).
"""

from __future__ import annotations

import logging
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pycolmap

from scenebot.sfm.config import SfmConfig
from scenebot.sfm.features import database_cache
from scenebot.sfm.mapping import (
    MappingResult,
    ObservationTable,
    _ba_options,
    mapping_options,
    position_priors,
)
from scenebot.sfm.photos import Photo

log = logging.getLogger(__name__)

MAX_ROUNDS = 8
"""Rounds of triangulation and adjustment at most."""
SETTLED_M = 0.005
"""The poses have settled when no camera centre moved more than this (m) in a round."""
ADJUSTMENTS = 3
"""Bundle adjustments per round, each after dropping the observations beyond the bound."""
FIRST_MAX_ANGLE_DEG = 8.0
"""The first triangulation's bound (deg) on the angle between a track's rays (COLMAP's: 2):
rays from tracked poses a drift off. The observations' bound then starts at three times
their median reprojection error and halves every round down to the mapper's own."""


def tracked_session(photos: list[Photo]) -> tuple[str, list[Photo]] | None:
    """The tracking session most photos belong to and its photos, or None when no photo has
    a tracked pose (or fewer than three share a session)."""
    sessions = Counter(p.motion.session for p in photos if p.motion is not None)
    if not sessions:
        return None
    session, n = sessions.most_common(1)[0]
    if n < 3:
        return None
    return session, [p for p in photos if p.motion is not None and p.motion.session == session]


def map_from_motion(
    db_path: Path,
    image_root: Path,
    photos: list[Photo],
    cfg: SfmConfig,
    fix_focal: bool,
) -> MappingResult | None:
    """Map the photos of the largest tracking session (:func:`tracked_session`) from their
    tracked poses (module docstring). The model is in the session's frame (metric, level).

    A photo whose placed pose ends with fewer observations than the mapper asks of any
    registration (``abs_pose_min_num_inliers``) leaves the map, with the reason.

    Returns:
        The mapping result (mode and mapper ``tracked``; ``refinement``: ``rounds``,
        ``moved_m`` of the last round, ``max_error_px``, ``prior_std_m``), or None when no
        session has three photos with features.
    """
    t0 = time.perf_counter()
    found = tracked_session(photos)
    if found is None:
        return None
    session, members = found
    names = [p.name for p in members]
    cache = database_cache(db_path, set(names), cfg.min_num_matches)
    rec = pycolmap.Reconstruction()
    mapper = pycolmap.IncrementalMapper(cache)
    mapper.begin_reconstruction(rec)
    opts = mapping_options(cfg, names, fix_focal=fix_focal)
    max_error = opts.get_mapper().filter_max_reproj_error
    min_obs = opts.get_mapper().abs_pose_min_num_inliers
    tracked = {p.name: p.motion for p in members}
    centres: dict[int, np.ndarray] = {}
    for iid, im in rec.images.items():
        m = tracked.get(im.name)
        if m is None:
            continue
        pose = pycolmap.Rigid3d(pycolmap.Rotation3d(m.rotation), -m.rotation @ m.center)
        rec.frame(im.frame_id).rig_from_world = pose
        mapper.observation_manager.register_frame(im.frame_id)
        centres[iid] = m.center
    if len(centres) < 3:
        mapper.end_reconstruction(True)
        return None
    delete = mapper.observation_manager.delete_observation
    ba = _ba_options(cfg.num_threads, not fix_focal, False, cauchy_px=1.0)
    prior_opts = pycolmap.PosePriorBundleAdjustmentOptions()
    prior_opts.prior_position_fallback_stddev = cfg.motion_prior_std_m
    ids = sorted(centres)
    placed = {rec.image(i).name for i in ids}
    moved, rounds, bound = float("inf"), 0, None
    while rounds < MAX_ROUNDS and (moved > SETTLED_M or bound > max_error):
        before = np.array([rec.image(i).projection_center() for i in ids])
        tri = opts.get_triangulation()
        if bound is None:  # the tracked poses' error: tracks from farther apart rays
            tri.create_max_angle_error = FIRST_MAX_ANGLE_DEG
            tri.continue_max_angle_error = FIRST_MAX_ANGLE_DEG
        for iid in ids:
            mapper.triangulate_image(tri, iid)
        if bound is None:
            errors = ObservationTable(rec).errors(rec)
            errors = errors[np.isfinite(errors)]
            bound = max(max_error, 3.0 * float(np.median(errors))) if len(errors) else max_error
        else:
            bound = max(max_error, bound / 2.0)
        for _ in range(ADJUSTMENTS):
            ObservationTable(rec).delete_beyond(rec, bound, delete)
            config = pycolmap.BundleAdjustmentConfig()
            for iid in ids:
                config.add_image(iid)
            priors = position_priors(rec, {i: centres[i] for i in ids}, cfg.motion_prior_std_m)
            pycolmap.create_pose_prior_bundle_adjuster(ba, prior_opts, config, priors, rec).solve()
        ObservationTable(rec).delete_beyond(rec, bound, delete)
        after = np.array([rec.image(i).projection_center() for i in ids])
        moved = float(np.max(np.linalg.norm(after - before, axis=1)))
        rounds += 1
        mapper.complete_and_merge_tracks(opts.get_triangulation())
        log.info("tracked map, round %d: %d points within %.1f px, poses moved up to %.3f m",
                 rounds, rec.num_points3D(), bound, moved)  # fmt: skip
    dropped: dict[str, str] = {}
    for iid in ids:
        im = rec.image(iid)
        if im.num_points3D < min_obs:
            mapper.observation_manager.deregister_frame(im.frame_id)
            dropped[im.name] = (
                f"placed at its tracked pose, {im.num_points3D} of its observations agree with "
                f"the map (the mapper registers a photo with {min_obs})"
            )
    mapper.end_reconstruction(False)
    rec.update_point_3d_errors()
    for iid in rec.reg_image_ids():
        rec.extract_colors_for_image(iid, str(image_root))
    for name in names:
        if name not in placed:
            dropped[name] = "no verified pair with another photo of its tracking session"
    for p in photos:
        if p.name not in tracked:
            dropped.setdefault(p.name, f"not of the tracking session {session}")
    res = MappingResult(rec, "tracked", 1, dropped, time.perf_counter() - t0)
    res.mapper = "tracked"
    res.refinement = {
        "session": session,
        "rounds": rounds,
        "moved_m": moved,
        "max_error_px": bound,
        "prior_std_m": cfg.motion_prior_std_m,
    }
    log.info(
        "mapped %d of %d photos of tracking session %s from their tracked poses in %.0f s "
        "(%d rounds)", rec.num_reg_images(), len(names), session, res.seconds, rounds,
    )  # fmt: skip
    return res


def tracked_residuals(rec: pycolmap.Reconstruction, photos: list[Photo]) -> dict[str, float]:
    """How far (m, the tracking's scale: the map's may be any) each registered photo with a
    tracked motion lies from where its tracking session puts it, the session's frame
    brought onto the map by its registered photos (:func:`session_to_map`, robust to a few
    photos registered off); photos of a session whose frame cannot be fitted are left
    out."""
    sessions = by_session(photos)
    out: dict[str, float] = {}
    for members in sessions.values():
        fit = session_to_map(rec, members)
        if fit is None:
            continue
        s, R, t, _ = fit
        for p in members:
            im = rec.find_image_with_name(p.name)
            if im is not None and im.has_pose:
                d = np.linalg.norm(s * R @ p.motion.center + t - im.projection_center())
                out[p.name] = float(d / s)
    return out


def pairs_the_tracking_disowns(
    contradicted: list[tuple[str, str, int, float]],
    residuals: dict[str, float],
    max_residual_m: float,
) -> list[tuple[str, str]]:
    """Of the pairs a tracked map does not hold (the person check's ``contradicted``), those
    whose two photos both lie where their tracking puts them (within ``max_residual_m``):
    the pair's matches are wrong (a repeating texture), not the photos' poses."""
    return [
        (a, b)
        for a, b, *_ in contradicted
        if residuals.get(a, np.inf) <= max_residual_m and residuals.get(b, np.inf) <= max_residual_m
    ]


MIN_SPAN_M = 0.5
"""Two registered photos of a session this far apart (m, tracked) or more fix its scale."""
SAME_ROTATION_DEG = 3.0
"""Registered photos whose session-to-map rotations agree within this (deg) vote together."""


def by_session(photos: list[Photo]) -> dict[str, list[Photo]]:
    """The photos with a tracked motion, by tracking session."""
    out: dict[str, list[Photo]] = {}
    for p in photos:
        if p.motion is not None:
            out.setdefault(p.motion.session, []).append(p)
    return out


def session_to_map(
    rec: pycolmap.Reconstruction, members: list[Photo]
) -> tuple[float, np.ndarray, np.ndarray, list[str]] | None:
    """The similarity from a tracking session's frame to the map, from the session's
    registered photos: the rotation that most photos' own poses agree with (each photo
    gives one: its map rotation against its tracked one), the scale the median ratio of
    their distances (pairs at least :data:`MIN_SPAN_M` apart in the tracking), the
    translation the median of their centres' offsets. Robust to a photo registered one
    motif off; None with fewer than two agreeing photos or no pair far enough apart.

    Returns:
        ``(s, R, t)`` with ``x_map = s R x_session + t``, and the photos it rests on.
    """
    reg = [(p, rec.find_image_with_name(p.name)) for p in members]
    reg = [(p, im) for p, im in reg if im is not None and im.has_pose]
    if len(reg) < 2:
        return None
    rots = [im.cam_from_world().rotation.matrix().T @ p.motion.rotation for p, im in reg]
    cos_same = np.cos(np.radians(SAME_ROTATION_DEG))

    def agree(Ra: np.ndarray) -> np.ndarray:
        return np.array([(np.trace(Ra.T @ Rb) - 1) / 2 >= cos_same for Rb in rots])

    votes = [agree(Ra) for Ra in rots]
    best = int(np.argmax([v.sum() for v in votes]))
    keep = votes[best]
    if keep.sum() < 2:
        return None
    u, _, vt = np.linalg.svd(sum(r for r, k in zip(rots, keep, strict=True) if k))
    R = u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt  # the chordal mean
    used = [pi for pi, k in zip(reg, keep, strict=True) if k]
    src = np.array([p.motion.center for p, _ in used])
    dst = np.array([im.projection_center() for _, im in used])
    i, j = np.triu_indices(len(used), 1)
    span = np.linalg.norm(src[i] - src[j], axis=1)
    far = span >= MIN_SPAN_M
    if not far.any():
        return None
    s = float(np.median(np.linalg.norm(dst[i] - dst[j], axis=1)[far] / span[far]))
    t = np.median(dst - s * src @ R.T, axis=0)
    return s, R, t, [p.name for p, _ in used]


def tracked_priors(
    rec: pycolmap.Reconstruction, photos: list[Photo], names: set[str]
) -> tuple[dict[str, pycolmap.Rigid3d], dict[str, str]]:
    """Where their tracked motion puts the photos ``names`` in the map (cam_from_world):
    each tracking session's frame brought onto the map through its registered photos
    (:func:`session_to_map`).

    Returns:
        Photo name -> pose, and photo name -> why it has none (no tracked motion, too few
        registered photos of its session).
    """
    out: dict[str, pycolmap.Rigid3d] = {}
    why: dict[str, str] = {}
    sessions = by_session(photos)
    for p in photos:
        if p.name in names and p.motion is None:
            why[p.name] = "no tracked motion"
    for session, members in sessions.items():
        todo = [p for p in members if p.name in names]
        if not todo:
            continue
        fit = session_to_map(rec, [p for p in members if p.name not in names])
        if fit is None:
            for p in todo:
                why[p.name] = (
                    f"fewer than two registered photos of its tracking session {session} "
                    f"agree on its frame, at least {MIN_SPAN_M} m apart"
                )
            continue
        s, R, t, _ = fit
        for p in todo:
            rot = p.motion.rotation @ R.T
            centre = s * R @ p.motion.center + t
            out[p.name] = pycolmap.Rigid3d(pycolmap.Rotation3d(rot), -rot @ centre)
    return out, why


def drop_off_tracking(
    rec: pycolmap.Reconstruction, photos: list[Photo], max_m: float
) -> dict[str, float]:
    """Deregister the photos registered farther than ``max_m`` (m, the tracking's scale) from
    where their tracking session puts them once its frame is brought onto the map by its
    registered photos (:func:`session_to_map`, robust to a few such photos): a close-up of a
    repeating wallpaper registers confidently one motif off, and the phone's tracking is
    independent evidence (the robot's estimate, for a robot:
    :func:`~scenebot.sfm.stage.drop_misplaced`). Sessions whose frame cannot be fitted are
    not checked. The points left with fewer than two observations are the caller's to delete.

    Returns:
        Name -> distance (m) of the photos taken out.
    """
    out = {n: d for n, d in tracked_residuals(rec, photos).items() if d > max_m}
    for name in out:
        rec.deregister_frame(rec.find_image_with_name(name).frame_id)
    return out
