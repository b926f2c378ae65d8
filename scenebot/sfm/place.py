"""Photos the map left out, placed where the robot knows it took them (or a person's phone).

Repeating texture (wallpaper, parquet, tiles) folds structure from motion: a group of photos
registers consistently one pattern period away from where it was taken, or not at all when
the wall it shows was only ever triangulated as its copy; the stage then rightly leaves such
photos out (:func:`~scenebot.sfm.stage.drop_misplaced`). The robot, though, knows where each
of them was taken, to centimetres: its visual localization against the previous map, gated
by its own odometry (``localization`` in the capture log). :func:`place_left_out_photos`
puts such a photo at that estimate (or at the pose its map matches give near it), registers
it, triangulates its matches with the map's photos and with the other placed photos, and
bundle-adjusts the placed photos and their new points (the map's own points held) with a
position prior at the estimate. A placed photo stays in the map only when enough of its
observations agree with its pose, its group of placed photos matches enough of the map's
own points (:func:`anchored_observations`), and the pose is still within the estimate's
tolerances; the others leave again, with the reason.

A person's phone tracks its own motion (:mod:`scenebot.sfm.tracked`): a guided round's photos
that do not register (close-ups of a repeating wallpaper: in the flat's guided campaign of
2026-11-28, 14 of 37) are placed the same way at the pose their tracking gives once the
round's registered photos bring its frame onto the map (:func:`~scenebot.sfm.tracked.
tracked_priors`), with the tracking's prior (``sfm.motion_prior_std_m``).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path

import pycolmap

from scenebot.geometry import map_mount
from scenebot.sfm.config import SfmConfig
from scenebot.sfm.features import database_cache
from scenebot.sfm.mapping import (
    ObservationTable,
    _ba_options,
    mapping_options,
    position_priors,
)
from scenebot.sfm.photos import Photo
from scenebot.sfm.register import (
    Tolerance,
    camera_centre,
    camera_priors,
    images_of,
    map_correspondences,
    points_of,
    pose_near_estimate,
)

log = logging.getLogger(__name__)


def robot_priors(
    rec: pycolmap.Reconstruction,
    photos: list[Photo],
    dropped: dict[str, str],
    camera_offset_m: tuple[float, float] | None,
    cfg: SfmConfig,
) -> dict[str, pycolmap.Rigid3d]:
    """Where the robot's estimate puts the photos of ``dropped`` that have one
    (cam_from_world, the map's camera height and mount pitch;
    :func:`~scenebot.sfm.register.camera_priors`)."""
    todo = [p for p in photos if p.name in dropped and p.localization is not None]
    if not todo or rec.num_reg_images() < 2:
        return {}
    height, pitch = map_mount(rec)
    return camera_priors(todo, camera_offset_m, cfg.camera_yaw_deg, height, pitch)


@dataclass(frozen=True)
class PriorSource:
    """Where the placed photos' poses come from: its name in messages, how far the
    adjustment may move a photo from it (:class:`~scenebot.sfm.register.Tolerance`) and the
    position prior's standard deviation (m)."""

    name: str
    tolerance: Tolerance
    prior_std_m: float


def robot_source(cfg: SfmConfig) -> PriorSource:
    """The robot's estimate: ``sfm.max_estimate_deviation_m``,
    ``sfm.max_compass_deviation_deg``, ``sfm.place_prior_std_m``."""
    return PriorSource(
        "the robot's estimate",
        Tolerance(cfg.max_estimate_deviation_m, cfg.max_compass_deviation_deg),
        cfg.place_prior_std_m,
    )


def tracked_source(cfg: SfmConfig) -> PriorSource:
    """A phone's tracked motion: its position known to ``sfm.motion_prior_std_m`` (also the
    prior), its heading to ``sfm.max_compass_deviation_deg``."""
    return PriorSource(
        "its tracked motion",
        Tolerance(cfg.motion_prior_std_m, cfg.max_compass_deviation_deg),
        cfg.motion_prior_std_m,
    )


def place_left_out_photos(
    rec: pycolmap.Reconstruction,
    db_path: Path,
    image_root: Path,
    photos: list[Photo],
    dropped: dict[str, str],
    priors: dict[str, pycolmap.Rigid3d],
    source: PriorSource,
    cfg: SfmConfig,
) -> dict:
    """Place the photos of ``dropped`` that have a prior pose at it and keep those the map
    then confirms (module docstring).

    Args:
        rec: the model in the robot frame (modified: placed photos registered, their
            points triangulated).
        db_path: the scene database (features and matches of all ``photos``).
        image_root: folder the photo names are relative to (point colours).
        photos: the photo set.
        dropped: photo name -> why it is not in the map (modified: placed photos leave
            it; photos placed and taken out again get the reason).
        priors: photo name -> its prior pose (cam_from_world, the map's frame):
            :func:`robot_priors`, :func:`~scenebot.sfm.tracked.tracked_priors`.
        source: what the priors are (:func:`robot_source`, :func:`tracked_source`).
        cfg: sfm settings (``refine_max_error_px``, ``refine_iterations``).

    Returns:
        report.json's ``placed``: ``source``, ``tried``, ``kept`` (names), ``from_matches``
        (photos whose starting pose came from their gated map matches), ``taken_out`` (name
        -> why), ``observations`` (name -> observations kept), ``seconds``.
    """
    t0 = time.perf_counter()
    stats: dict = {
        "source": source.name, "tried": 0, "kept": [], "from_matches": 0, "taken_out": {},
        "observations": {}, "anchored": {},
    }  # fmt: skip
    todo = [p for p in photos if p.name in dropped and p.name in priors]
    if not todo or rec.num_reg_images() < 2:
        return stats | {"seconds": time.perf_counter() - t0}
    names = [p.name for p in photos]
    cache = database_cache(db_path, set(names), cfg.min_num_matches)
    opts = mapping_options(cfg, names, continuing=True, fix_focal=True)
    mapper = pycolmap.IncrementalMapper(cache)
    mapper.begin_reconstruction(rec)
    tolerance = source.tolerance
    min_obs = opts.get_mapper().abs_pose_min_num_inliers
    existing = set(rec.point3D_ids())  # the map's own points: held in the adjustment
    placed: dict[int, pycolmap.Rigid3d] = {}
    for p in todo:
        im = rec.find_image_with_name(p.name)
        if im is None:  # not in the database (no features)
            continue
        iid = im.image_id
        pose = _starting_pose(
            rec, cache.correspondence_graph, iid, priors[p.name], tolerance, cfg, min_obs
        )
        if pose is not priors[p.name]:
            stats["from_matches"] += 1
        rec.frame(im.frame_id).rig_from_world = pose
        mapper.observation_manager.register_frame(im.frame_id)
        placed[iid] = priors[p.name]
    stats["tried"] = len(placed)
    tri = opts.get_triangulation()
    for _ in range(2):  # again from the adjusted poses: tracks the first poses missed
        for iid in placed:  # every placed photo registered first: they triangulate together
            mapper.triangulate_image(tri, iid)
        _adjust_placed(mapper, placed, existing, cfg, source.prior_std_m)
    anchors, group_anchors = anchored_observations(rec, set(placed), existing)
    for iid, prior in placed.items():
        im = rec.image(iid)
        n_obs = im.num_points3D
        why = _why_not_kept(
            im.cam_from_world(), prior, n_obs, group_anchors[iid], tolerance, min_obs
        )
        if why:
            mapper.observation_manager.deregister_frame(im.frame_id)
            stats["taken_out"][im.name] = why
            dropped[im.name] = f"{dropped[im.name]}; placed at {source.name}: {why}"
            continue
        stats["kept"].append(im.name)
        stats["observations"][im.name] = n_obs
        stats["anchored"][im.name] = anchors[iid]
        dropped.pop(im.name, None)
    mapper.end_reconstruction(False)
    for iid in placed:
        if rec.exists_image(iid) and rec.image(iid).has_pose:
            rec.extract_colors_for_image(iid, str(image_root))
    stats["seconds"] = time.perf_counter() - t0
    if placed:
        log.info(
            "placed %d left-out photo(s) at %s: %d kept, %d taken out again",
            len(placed),
            source.name,
            len(stats["kept"]),
            len(stats["taken_out"]),
        )
    return stats


def _starting_pose(
    rec: pycolmap.Reconstruction,
    graph: pycolmap.CorrespondenceGraph,
    iid: int,
    prior: pycolmap.Rigid3d,
    tolerance: Tolerance,
    cfg: SfmConfig,
    min_inliers: int,
) -> pycolmap.Rigid3d:
    """The pose the photo's matches to map points give within the tolerances of its prior
    (the robot's estimate, the tracked motion;
    :func:`~scenebot.sfm.register.pose_near_estimate`: more exact than the prior), else the
    prior itself."""
    _, xy, xyz = map_correspondences(rec, graph, iid, every=True)
    pose = pose_near_estimate(
        rec.image(iid).camera, prior, xy, xyz, tolerance, cfg.refine_max_error_px,
        min_inliers,
    )  # fmt: skip
    return prior if pose is None else pose


def _adjust_placed(
    mapper: pycolmap.IncrementalMapper,
    placed: dict[int, pycolmap.Rigid3d],
    existing: set[int],
    cfg: SfmConfig,
    prior_std_m: float,
) -> None:
    """``cfg.refine_iterations`` times: drop the placed photos' points' observations beyond
    ``cfg.refine_max_error_px``, then bundle-adjust the placed photos and their points
    (Cauchy loss, 1 px) with a position prior (``prior_std_m``) at their prior pose; every
    other pose and the intrinsics held. Filters once more at the end (through the mapper's
    observation manager, which keeps count for triangulation)."""
    rec = mapper.reconstruction
    delete = mapper.observation_manager.delete_observation
    ids = [i for i in placed if rec.image(i).has_pose]
    points = points_of(rec, ids)
    if not points:
        return
    table = ObservationTable(rec, images_of(rec, points), points)
    opts = _ba_options(cfg.num_threads, False, False, cauchy_px=1.0)
    prior_opts = pycolmap.PosePriorBundleAdjustmentOptions()
    prior_opts.prior_position_fallback_stddev = prior_std_m
    centres = {iid: camera_centre(placed[iid]) for iid in ids}
    for _ in range(max(cfg.refine_iterations, 1)):
        table.delete_beyond(rec, cfg.refine_max_error_px, delete)
        config = pycolmap.BundleAdjustmentConfig()
        for iid in ids:
            config.add_image(iid)
        priors = position_priors(rec, centres, prior_std_m)
        for pid in points:  # the map's own points held; new ones with every observation
            if not rec.exists_point3D(pid):
                continue
            if pid in existing:
                config.add_constant_point(pid)
            else:
                config.add_variable_point(pid)
        pycolmap.create_pose_prior_bundle_adjuster(opts, prior_opts, config, priors, rec).solve()
    table.delete_beyond(rec, cfg.refine_max_error_px, delete)


def anchored_observations(
    rec: pycolmap.Reconstruction, placed: set[int], existing: set[int]
) -> tuple[dict[int, int], dict[int, int]]:
    """How firmly the map holds each placed photo: its observations of the map's own points
    (``existing``, held in the adjustment: a 2D-3D match as any registration counts it),
    and those summed over its group (the placed photos connected through points they
    share: triangulated together, such a group is one rigid body, which the map holds like
    one camera). Points a placed photo triangulated with the map's photos do not count: a
    pose a metre off still finds rays that meet somewhere.

    Returns:
        Image id -> its anchored observations, and image id -> its group's.
    """
    parent = {i: i for i in placed}

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    anchors = dict.fromkeys(placed, 0)
    for iid in placed:
        for p2 in rec.image(iid).get_observation_points2D():
            track = {e.image_id for e in rec.point3D(p2.point3D_id).track.elements}
            if p2.point3D_id in existing:
                anchors[iid] += 1
            for other in track & placed:
                parent[root(other)] = root(iid)
    group: dict[int, int] = {}
    for iid in placed:
        group[root(iid)] = group.get(root(iid), 0) + anchors[iid]
    return anchors, {iid: group[root(iid)] for iid in placed}


def _why_not_kept(
    pose: pycolmap.Rigid3d,
    prior: pycolmap.Rigid3d,
    n_obs: int,
    group_anchors: int,
    tolerance: Tolerance,
    min_obs: int,
) -> str | None:
    """Why a placed photo leaves the map again (None: it stays), ``min_obs`` being the
    inliers the mapper asks of any registration: fewer observations agree with its pose
    (too few to pin it to the pixel); its group holds fewer anchored observations
    (:func:`anchored_observations`: placed photos that only see each other agree with a
    shared error of their estimates as well as with the truth); or the adjustment moved it
    beyond the estimate's tolerances."""
    if n_obs < min_obs:
        return f"{n_obs} observations agree with it (the mapper registers a photo with {min_obs})"
    if group_anchors < min_obs:
        return (
            f"it and the photos placed with it share {group_anchors} observations with the "
            f"map (the mapper registers a photo with {min_obs})"
        )
    if not tolerance.agrees(pose, prior):
        return (
            f"the adjustment moved it beyond {tolerance.position_m:g} m / "
            f"{tolerance.heading_deg:g} deg of its prior pose"
        )
    return None
