"""Incremental mapping (pycolmap), from scratch or continuing a previous round's model;
global SfM when the incremental mapper leaves out photos the view graph connects."""

from __future__ import annotations

import itertools
import logging
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pycolmap

from scenebot.sfm.config import SfmConfig
from scenebot.sfm.features import open_database

log = logging.getLogger(__name__)


class SfmError(RuntimeError):
    """The photo set did not give a usable map; the message names the photos and the fix."""


@dataclass
class MappingResult:
    """The kept model and what happened to every photo.

    Attributes:
        reconstruction: the largest model.
        mode: ``"scratch"``, ``"incremental"``, ``"incremental->scratch"`` (fallback),
            ``"registered"`` (the new photos registered into the previous model, see
            :mod:`scenebot.sfm.register`) or ``"registered+global"`` (and the global
            refinement run after it).
        num_models: how many models mapping produced.
        dropped: photo name -> reason, for photos not in the kept model.
        seconds: wall time of mapping.
        refinement: stats of the final robust refinement (empty when off).
        attempts: mapping runs from scratch (``cfg.mapping_attempts`` at most; 0 when
            continuing from the previous model sufficed).
        new_ids: ``registered`` modes: image ids of the photos registered now.
        mapper: ``"incremental"`` or ``"global"`` (global SfM kept, see
            :func:`global_sfm_fallback`).
        global_sfm: the global-SfM fallback's decision (report.json ``global_sfm``): why
            it ran, both models' photo counts, which was kept; empty when it did not run.
        overruled: ``registered`` modes: photos that registered but were taken out again
            against the robot's estimate (the slow path keeps such photos in its model
            until the stage leaves them out, so they count as registered toward
            ``min_registered_share`` on both paths).
    """

    reconstruction: pycolmap.Reconstruction
    mode: str
    num_models: int
    dropped: dict[str, str] = field(default_factory=dict)
    seconds: float = 0.0
    refinement: dict = field(default_factory=dict)
    attempts: int = 0
    new_ids: list[int] = field(default_factory=list)
    mapper: str = "incremental"
    overruled: int = 0
    global_sfm: dict = field(default_factory=dict)

    @property
    def continued(self) -> bool:
        """The model grew from the previous round's, whose photo poses it keeps."""
        return self.mode in CONTINUED_MODES


CONTINUED_MODES = ("incremental", "registered", "registered+global")
"""Mapping modes that continue from the previous round's model."""


class ObservationTable:
    """The observations of registered images as arrays (image id, point2D index, 3D point
    id, pixel position): reading them from pycolmap point by point costs about a second per
    pass on a 200-photo map, so a refinement reads them once and filters them repeatedly.

    Args:
        rec: the model.
        image_ids: the images whose observations are read (default: all registered).
        point_ids: only observations of these 3D points (default: all).
    """

    def __init__(
        self,
        rec: pycolmap.Reconstruction,
        image_ids=None,
        point_ids: set[int] | None = None,
    ) -> None:
        rows: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        for iid in rec.reg_image_ids() if image_ids is None else image_ids:
            im = rec.image(iid)
            pts = im.get_observation_points2D()
            if not len(pts):
                continue
            idx = np.asarray(im.get_observation_point2D_idxs(), np.int64)
            ids = np.array([p.point3D_id for p in pts], np.int64)
            xy = np.array([p.xy for p in pts])
            if point_ids is not None:
                keep = np.isin(ids, np.fromiter(point_ids, np.int64, len(point_ids)))
                idx, ids, xy = idx[keep], ids[keep], xy[keep]
            rows.append((np.full(len(idx), iid, np.int64), idx, ids, xy))
        empty = (np.zeros(0, np.int64),) * 3 + (np.zeros((0, 2)),)
        cols = list(zip(*rows, strict=True)) if rows else [[c] for c in empty]
        self.image_ids, self.point2D_idx, self.point3D_ids, self.xy = (
            np.concatenate(c) for c in cols
        )

    def __len__(self) -> int:
        return len(self.image_ids)

    def _keep(self, sel: np.ndarray) -> None:
        self.image_ids, self.point2D_idx = self.image_ids[sel], self.point2D_idx[sel]
        self.point3D_ids, self.xy = self.point3D_ids[sel], self.xy[sel]

    def errors(self, rec: pycolmap.Reconstruction) -> np.ndarray:
        """Reprojection errors (px) at the current poses and points, ``inf`` behind the
        camera; rows whose point or image is gone are dropped first."""
        pids, inverse = np.unique(self.point3D_ids, return_inverse=True)
        exists = np.array([rec.exists_point3D(int(p)) for p in pids], bool)
        alive = exists[inverse] & np.isin(
            self.image_ids, np.fromiter(rec.reg_image_ids(), np.int64)
        )
        xyz = np.zeros((len(pids), 3))
        xyz[exists] = np.reshape([rec.point3D(int(p)).xyz for p in pids[exists]], (-1, 3))
        X = xyz[inverse[alive]]
        self._keep(alive)
        err = np.empty(len(self))
        if not len(self):
            return err
        starts = np.r_[0, np.flatnonzero(np.diff(self.image_ids)) + 1, len(self)]
        for a, b in itertools.pairwise(starts):  # rows grouped by image
            im = rec.image(int(self.image_ids[a]))
            cam_pts = im.cam_from_world() * X[a:b]
            uv = im.camera.img_from_cam(cam_pts, check_cheirality=False)
            err[a:b] = np.linalg.norm(uv - self.xy[a:b], axis=1)
            err[a:b][cam_pts[:, 2] <= 0] = np.inf
        return err

    def delete_beyond(self, rec: pycolmap.Reconstruction, max_error_px: float, delete=None) -> int:
        """Delete the observations whose reprojection error exceeds ``max_error_px`` (px)
        or is not finite from ``rec`` and the table; returns how many. ``delete(image_id,
        point2D_idx)`` deletes one (default ``rec.delete_observation``; an incremental
        mapper's ``observation_manager.delete_observation`` keeps its bookkeeping)."""
        delete = delete or rec.delete_observation
        err = self.errors(rec)
        bad = ~(err <= max_error_px)
        for iid, k in zip(self.image_ids[bad], self.point2D_idx[bad], strict=True):
            if rec.image(int(iid)).point2D(int(k)).has_point3D():
                delete(int(iid), int(k))
        self._keep(~bad)
        return int(bad.sum())


def delete_far_points(rec: pycolmap.Reconstruction, point_ids: set[int] | None = None) -> int:
    """Delete the 3D points (of ``point_ids``, default all) that are not finite or lie
    farther than 1000 times the cameras' extent from their median centre; returns how
    many."""
    centers = np.array([rec.image(i).projection_center() for i in rec.reg_image_ids()])
    mid = np.median(centers, 0)
    extent = max(float(np.max(np.linalg.norm(centers - mid, axis=1))), 1e-9)
    far = [
        pid
        for pid, pt in rec.points3D.items()
        if (point_ids is None or pid in point_ids)
        and (not np.all(np.isfinite(pt.xyz)) or np.linalg.norm(pt.xyz - mid) > 1000 * extent)
    ]
    for pid in far:
        rec.delete_point3D(pid)
    return len(far)


def filter_observations(
    rec: pycolmap.Reconstruction,
    max_error_px: float,
    table: ObservationTable | None = None,
    point_ids: set[int] | None = None,
) -> int:
    """Delete observations whose reprojection error exceeds ``max_error_px`` (px) and points
    that are not finite or lie far outside the cameras' extent; with ``table``, only the
    observations it holds (and it is updated), with ``point_ids`` only those points.

    Returns:
        The number of observations deleted.
    """
    far = delete_far_points(rec, point_ids)
    if table is None:
        table = ObservationTable(rec, point_ids=point_ids)
    return table.delete_beyond(rec, max_error_px) + far


def robust_refinement(
    rec: pycolmap.Reconstruction,
    max_error_px: float,
    iterations: int,
    num_threads: int,
    relax_first: bool = False,
    refine_focal_length: bool = True,
    *,
    refine_extra_params: bool,
    constant_names: frozenset[str] | set[str] = frozenset(),
) -> dict:
    """Final robust bundle adjustment: drop observations beyond ``max_error_px``, then
    global BA with a Cauchy loss (scale 1 px), ``iterations`` times, and filter once more.
    ``constant_names``: photos whose poses stay fixed (a previous round's, so a round update
    only adds to the map and never bends what later stages and the robot already used).

    COLMAP's incremental mapper keeps observations up to 4 px with a squared loss; in scenes
    with view-dependent features (highlights, occlusion corners) those bend the camera
    trajectory by centimetres. ``refine_focal_length`` / ``refine_extra_params``: whether
    the bundle adjustments refine the focal length and the distortion (the principal point
    is never refined). Returns stats (observations removed, reprojection error px).
    """
    before = rec.compute_mean_reprojection_error()
    removed = 0
    if relax_first:
        opts = _ba_options(num_threads, refine_focal_length, refine_extra_params)
        _adjust(rec, opts, constant_names)
    table = ObservationTable(rec)
    for _ in range(iterations):
        removed += filter_observations(rec, max_error_px, table)
        opts = _ba_options(num_threads, refine_focal_length, refine_extra_params, cauchy_px=1.0)
        _adjust(rec, opts, constant_names)
    removed += filter_observations(rec, max_error_px, table)
    return {
        "observations_removed": removed,
        "reprojection_error_before_px": before,
        "reprojection_error_after_px": rec.compute_mean_reprojection_error(),
    }


def _adjust(
    rec: pycolmap.Reconstruction,
    opts: pycolmap.BundleAdjustmentOptions,
    constant_names: frozenset[str] | set[str],
) -> None:
    """Global bundle adjustment, the poses of ``constant_names`` held fixed."""
    fixed = [i for i in rec.reg_image_ids() if rec.image(i).name in constant_names]
    if not fixed:
        pycolmap.bundle_adjustment(rec, opts)
        return
    config = pycolmap.BundleAdjustmentConfig()
    for iid in rec.reg_image_ids():
        config.add_image(iid)
    for iid in fixed:
        config.set_constant_rig_from_world_pose(rec.image(iid).frame_id)
    pycolmap.create_default_bundle_adjuster(opts, config, rec).solve()


def _ba_options(
    num_threads: int,
    refine_focal_length: bool,
    refine_extra_params: bool,
    cauchy_px: float | None = None,
) -> pycolmap.BundleAdjustmentOptions:
    """Bundle adjustment options: the principal point held; with ``cauchy_px`` a Cauchy loss
    of that scale (px) instead of the squared error."""
    opts = pycolmap.BundleAdjustmentOptions()
    opts.print_summary = False
    opts.refine_focal_length = refine_focal_length
    opts.refine_principal_point = False
    opts.refine_extra_params = refine_extra_params
    opts.ceres.solver_options.num_threads = num_threads
    if cauchy_px is not None:
        opts.ceres.loss_function_type = pycolmap.LossFunctionType.CAUCHY
        opts.ceres.loss_function_scale = cauchy_px
    return opts


def position_priors(
    rec: pycolmap.Reconstruction, positions: dict[int, np.ndarray], std_m: float
) -> list[pycolmap.PosePrior]:
    """Position priors (isotropic, ``std_m`` m) on the camera centres of images (id ->
    (3,) position, m); non-finite positions get none."""
    cov = np.eye(3) * std_m**2
    priors = []
    for iid, p in positions.items():
        if np.all(np.isfinite(p)):
            prior = pycolmap.PosePrior()
            prior.corr_data_id = rec.image(iid).data_id
            prior.position = np.asarray(p, np.float64)
            prior.position_covariance = cov
            prior.coordinate_system = pycolmap.PosePriorCoordinateSystem.CARTESIAN
            priors.append(prior)
    return priors


def _pipeline_options(opts, cfg: SfmConfig, names: list[str]):
    """What the incremental and the global pipelines' options share: threads, seed, the
    fewest matches of a pair, the photos to map."""
    opts.num_threads = cfg.num_threads
    opts.random_seed = cfg.random_seed
    opts.min_num_matches = cfg.min_num_matches
    opts.image_names = list(names)
    return opts


def mapping_options(
    cfg: SfmConfig, names: list[str], continuing: bool = False, fix_focal: bool = False
) -> pycolmap.IncrementalPipelineOptions:
    opts = _pipeline_options(pycolmap.IncrementalPipelineOptions(), cfg, names)
    opts.multiple_models = True
    opts.extract_colors = True
    opts.ba_refine_focal_length = not fix_focal
    opts.ba_refine_principal_point = False
    opts.ba_refine_extra_params = cfg.refine_distortion
    opts.mapper.abs_pose_refine_focal_length = not fix_focal
    opts.mapper.abs_pose_refine_extra_params = cfg.refine_distortion
    ratio = cfg.update_global_ba_ratio if continuing else cfg.global_ba_ratio
    opts.ba_global_frames_ratio = ratio
    opts.ba_global_points_ratio = ratio
    if continuing:
        opts.fix_existing_frames = cfg.update_fix_existing
    return opts


def _run(
    db_path: Path,
    image_root: Path,
    work: Path,
    cfg: SfmConfig,
    names: list[str],
    input_model: pycolmap.Reconstruction | None,
    fix_focal: bool = False,
) -> dict[int, pycolmap.Reconstruction]:
    if work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)
    input_path = ""
    if input_model is not None:
        input_path = work / "input"
        input_path.mkdir()
        input_model.write_binary(str(input_path))
    out = work / "models"
    out.mkdir()
    return pycolmap.incremental_mapping(
        str(db_path),
        str(image_root),
        str(out),
        options=mapping_options(
            cfg, names, continuing=input_model is not None, fix_focal=fix_focal
        ),
        input_path=str(input_path),
    )


def _largest(models: dict[int, pycolmap.Reconstruction]) -> int:
    return max((r.num_reg_images() for r in models.values()), default=0)


def _scratch(
    db_path: Path,
    image_root: Path,
    work: Path,
    cfg: SfmConfig,
    names: list[str],
    fix_focal: bool,
) -> tuple[dict[int, pycolmap.Reconstruction], int]:
    """Map from scratch; run again with the next seed (``cfg.mapping_attempts`` runs at
    most) while the largest model holds fewer than ``cfg.min_registered_share`` of the
    photos, and keep the run whose largest model is largest.

    Returns:
        The kept run's models and the number of runs.
    """
    best: dict[int, pycolmap.Reconstruction] = {}
    for attempt in range(cfg.mapping_attempts):
        run_cfg = cfg.model_copy(update={"random_seed": cfg.random_seed + attempt})
        models = _run(
            db_path, image_root, work / f"attempt_{attempt}", run_cfg, names, None, fix_focal
        )
        if _largest(models) > _largest(best):
            best = models
        n = _largest(best)
        if n >= cfg.min_registered_share * len(names):
            break
        if attempt + 1 < cfg.mapping_attempts:
            log.warning(
                "mapping run %d (seed %d) registered %d of %d photos in its largest model: "
                "running again with seed %d (sfm.mapping_attempts = %d)",
                attempt + 1,
                run_cfg.random_seed,
                _largest(models),
                len(names),
                run_cfg.random_seed + 1,
                cfg.mapping_attempts,
            )
    return best, attempt + 1


def verified_pairs(db_path: Path, min_num_matches: int) -> dict[str, set[str]]:
    """The view graph: photo name -> names of the photos it shares a geometrically verified
    pair of at least ``min_num_matches`` inlier matches with."""
    graph: dict[str, set[str]] = {}
    with open_database(db_path) as db:
        names = {im.image_id: im.name for im in db.read_all_images()}
        pair_ids, inliers = db.read_two_view_geometry_num_inliers()
    for pid, n in zip(pair_ids, inliers, strict=True):
        if n >= min_num_matches:
            a, b = (names[i] for i in pycolmap.pair_id_to_image_pair(pid))
            graph.setdefault(a, set()).add(b)
            graph.setdefault(b, set()).add(a)
    return graph


def connected_left_out(graph: dict[str, set[str]], names: list[str], kept: set[str]) -> list[str]:
    """The photos of ``names`` outside ``kept`` that a chain of verified pairs (within
    ``names``) connects to a photo of ``kept``, in the order of ``names``."""
    allowed = set(names)
    reached, todo = set(kept), list(kept)
    while todo:
        for other in graph.get(todo.pop(), ()):
            if other in allowed and other not in reached:
                reached.add(other)
                todo.append(other)
    return [n for n in names if n in reached and n not in kept]


def _global_options(cfg: SfmConfig, names: list[str], fix_focal: bool):
    """pycolmap's global SfM options from the settings (CPU, seeded, our intrinsics
    policy: principal point fixed, focal refined unless held at EXIF)."""
    opts = _pipeline_options(pycolmap.GlobalPipelineOptions(), cfg, names)
    opts.mapper.num_threads = cfg.num_threads
    opts.mapper.random_seed = cfg.random_seed
    opts.mapper.global_positioning.use_gpu = False
    ba = opts.mapper.bundle_adjustment
    ba.ceres.use_gpu = False
    ba.refine_focal_length = not fix_focal
    ba.refine_principal_point = False
    ba.refine_extra_params = cfg.refine_distortion
    return opts


def _global_mapping(
    db_path: Path, image_root: Path, work: Path, cfg: SfmConfig, names: list[str], fix_focal: bool
) -> dict[int, pycolmap.Reconstruction]:
    """pycolmap's global SfM of ``names`` into ``work/global`` (replaced); its models."""
    out = work / "global"
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    return pycolmap.global_mapping(
        str(db_path), str(image_root), str(out), _global_options(cfg, names, fix_focal)
    )


def global_sfm_fallback(
    db_path: Path,
    image_root: Path,
    work: Path,
    cfg: SfmConfig,
    names: list[str],
    models: dict[int, pycolmap.Reconstruction],
    fix_focal: bool,
) -> tuple[dict[int, pycolmap.Reconstruction], str, dict]:
    """Global SfM when incremental mapping from scratch left out connected photos (the
    caller checks ``cfg.global_sfm_fallback``).

    The incremental mapper registers a photo from 2D-3D matches to points that two
    registered photos already triangulated (at least ``abs_pose_min_num_inliers`` = 30);
    a photo whose verified pairs lead only to features no third registered photo sees (a
    wide gap between views) is never tried, and a few such photos form a small model that
    COLMAP discards (``min_model_size``). Global SfM estimates every photo's rotation and
    position from the verified pairs directly, so any photo the view graph connects can be
    registered. Its model is kept when it registers more photos than the incremental one.

    Args:
        db_path, image_root, work, cfg, names, fix_focal: as :func:`map_photos`.
        models: the incremental mapper's models.

    Returns:
        The models kept, the mapper that made them (``incremental`` or ``global``), and
        the decision (empty when the fallback did not run): ``left_out`` (the connected
        photos the incremental model lacks), ``incremental_registered``,
        ``global_registered``, ``kept``, ``seconds``.
    """
    n_inc = _largest(models)
    best = max(models.values(), key=lambda r: r.num_reg_images(), default=None)
    kept = set() if best is None else {best.image(i).name for i in best.reg_image_ids()}
    if not kept:
        return models, "incremental", {}
    left = connected_left_out(verified_pairs(db_path, cfg.min_num_matches), names, kept)
    if not left:
        return models, "incremental", {}
    t = time.perf_counter()
    try:
        glob = _global_mapping(db_path, image_root, work, cfg, names, fix_focal)
    except Exception as exc:  # pycolmap raises RuntimeError/ValueError on bad input
        log.warning("global SfM failed (%s): keeping the incremental model", exc)
        glob = {}
    n_glob = _largest(glob)
    disagreement = _disagreement(best, max(glob.values(), key=lambda r: r.num_reg_images(),
                                           default=None))  # fmt: skip
    agrees = disagreement is not None and disagreement <= cfg.global_max_disagreement
    kept_mapper = "global" if n_glob > n_inc and agrees else "incremental"
    decision = {
        "left_out": left,
        "incremental_registered": n_inc,
        "global_registered": n_glob,
        "disagreement": disagreement,
        "kept": kept_mapper,
        "seconds": time.perf_counter() - t,
    }
    if n_glob > n_inc and not agrees:
        log.warning(
            "global SfM registered more photos but its cameras disagree with the incremental "
            "model's by %s of the map's size (sfm.global_max_disagreement = %g): keeping the "
            "incremental model",
            "an unknown share" if disagreement is None else f"{disagreement:.1%}",
            cfg.global_max_disagreement,
        )
    log.warning(
        "incremental mapping left out %d photo(s) that verified pairs connect to its model "
        "(%s): global SfM registered %d of %d photos against %d; keeping the %s model "
        "(sfm.global_sfm_fallback)",
        len(left),
        ", ".join(left[:10]) + (" ..." if len(left) > 10 else ""),
        n_glob,
        len(names),
        n_inc,
        kept_mapper,
    )
    return (glob if kept_mapper == "global" else models), kept_mapper, decision


def _disagreement(
    inc: pycolmap.Reconstruction | None, glob: pycolmap.Reconstruction | None
) -> float | None:
    """Median distance between the two models' camera centres on the photos both registered,
    after a similarity fit of the global onto the incremental, as a share of the incremental
    cameras' median distance from their centroid; None with fewer than 3 shared photos."""
    from scenebot.sfm.evaluate import umeyama

    if inc is None or glob is None:
        return None
    a = {inc.image(i).name: inc.image(i).projection_center() for i in inc.reg_image_ids()}
    b = {glob.image(i).name: glob.image(i).projection_center() for i in glob.reg_image_ids()}
    shared = sorted(a.keys() & b.keys())
    if len(shared) < 3:
        return None
    dst = np.array([a[n] for n in shared], np.float64)
    src = np.array([b[n] for n in shared], np.float64)
    s, R, t = umeyama(src, dst)
    resid = np.linalg.norm(s * src @ R.T + t - dst, axis=1)
    size = float(np.median(np.linalg.norm(dst - dst.mean(0), axis=1)))
    return float(np.median(resid) / size) if size > 0 else None


def _reasons(db_path: Path, names: list[str], kept: set[str], others: set[str], cfg) -> dict:
    """Why each photo outside the kept model dropped."""
    dropped: dict[str, str] = {}
    with open_database(db_path) as db:
        ids = {im.name: im.image_id for im in db.read_all_images()}
        pair_ids, inliers = db.read_two_view_geometry_num_inliers()
        good: dict[int, int] = {}
        for pid, n in zip(pair_ids, inliers, strict=True):
            if n < cfg.min_num_matches:
                continue
            a, b = pycolmap.pair_id_to_image_pair(pid)
            good[a] = good.get(a, 0) + 1
            good[b] = good.get(b, 0) + 1
        for name in names:
            if name in kept:
                continue
            iid = ids.get(name)
            if iid is None or db.num_keypoints_for_image(iid) == 0:
                dropped[name] = "no SIFT features (blank, dark or unreadable photo)"
            elif good.get(iid, 0) == 0:
                dropped[name] = (
                    "no verified matches with any paired photo (too little overlap or texture)"
                )
            elif name in others:
                dropped[name] = "in a separate, smaller model (no overlap with the main part)"
            else:
                dropped[name] = f"could not be registered ({good[iid]} matched pairs)"
    return dropped


def map_photos(
    db_path: Path,
    image_root: Path,
    names: list[str],
    work: Path,
    cfg: SfmConfig,
    previous: pycolmap.Reconstruction | None = None,
    fix_focal: bool = False,
    person_photos: bool = False,
    held: pycolmap.Reconstruction | None = None,
) -> MappingResult:
    """Map the photos ``names``; keep the largest model.

    With ``previous`` (round r-1's model, same database) and ``cfg.incremental``, mapping
    continues from it: the new photos are registered, then bundle adjustment refines all.
    When fewer than ``cfg.min_registered_share`` of the photos register that way, mapping
    runs again from scratch. From scratch, when the incremental model leaves out photos
    that verified pairs connect to it, global SfM maps the set too and the model with more
    photos is kept (:func:`global_sfm_fallback`).

    Args:
        db_path: the scene database (features and matches of all ``names``).
        image_root: folder the names are relative to (for point colours).
        names: photos to map.
        work: scratch folder (replaced).
        cfg: sfm settings.
        previous: model to continue from, or ``None``.
        fix_focal: keep every camera's focal length at its database prior (EXIF) in all
            bundle adjustments and pose estimates.
        person_photos: the photos are a person's photo folder (``robot: photos``), for
            ``cfg.global_sfm_fallback = "photos"``.
        held: the model whose photos keep their poses in the final refinement
            (``cfg.update_keep_previous_poses``; default ``previous``: round r-1's map when
            ``previous`` also holds photos registered this round).

    Returns:
        The kept model and the dropped photos with reasons.
    """
    t0 = time.perf_counter()
    mode = "scratch"
    models: dict[int, pycolmap.Reconstruction] = {}
    if previous is not None and cfg.incremental:
        models, mode = _continue(db_path, image_root, work, cfg, names, previous, fix_focal)
    attempts = 0
    if not models:
        models, attempts = _scratch(db_path, image_root, work, cfg, names, fix_focal)
    if not models:
        dropped = _reasons(db_path, names, set(), set(), cfg)
        raise SfmError(
            f"mapping found no model in {attempts} run(s) (sfm.mapping_attempts): no initial "
            "pair of photos with enough verified matches. "
            "Photos need overlap and texture; first photos without matches: "
            + ", ".join(list(dropped)[:10])
        )
    mapper, global_sfm = "incremental", {}
    use_global = cfg.global_sfm_fallback == "always" or (
        cfg.global_sfm_fallback == "photos" and person_photos
    )
    if attempts and use_global:
        models, mapper, global_sfm = global_sfm_fallback(
            db_path, image_root, work, cfg, names, models, fix_focal
        )
    ranked = sorted(models.values(), key=lambda r: r.num_reg_images(), reverse=True)
    best = ranked[0]
    kept_previous: frozenset[str] = frozenset()
    held = previous if held is None else held
    if mode == "incremental" and cfg.update_keep_previous_poses and held is not None:
        prev_names = {held.image(i).name for i in held.reg_image_ids()}
        kept_previous = frozenset(
            best.image(i).name for i in best.reg_image_ids() if best.image(i).name in prev_names
        )
    dropped = dropped_photos(db_path, names, ranked, cfg)
    res = MappingResult(best, mode, len(ranked), dropped, attempts=attempts)
    res.mapper, res.global_sfm = mapper, global_sfm
    refine_globally(res, db_path, image_root, work, cfg, names, fix_focal, kept_previous)
    res.seconds = time.perf_counter() - t0
    return res


def map_globally(
    db_path: Path,
    image_root: Path,
    names: list[str],
    work: Path,
    cfg: SfmConfig,
    fix_focal: bool = False,
) -> MappingResult:
    """Map the photos ``names`` with global SfM (pycolmap's GLOMAP: rotations averaged over
    every verified pair at once, then global positioning), keep the largest model and refine
    it as :func:`map_photos` does; mode ``scratch``, mapper ``global``.

    A loop of photos (a person's walk around a room) closes in global SfM by construction;
    the incremental mapper grows the model along the loop, and a stretch of weakly
    registered photos can fold it there before the loop closes (report.json
    ``person_check``).

    Raises:
        SfmError: no model (the message names the photos without verified matches).
    """
    t0 = time.perf_counter()
    try:
        models = _global_mapping(db_path, image_root, work, cfg, names, fix_focal)
    except Exception as exc:  # pycolmap raises RuntimeError/ValueError on bad input
        raise SfmError(f"global SfM failed: {exc}") from exc
    if not models:
        dropped = _reasons(db_path, names, set(), set(), cfg)
        raise SfmError(
            "global SfM found no model; first photos without matches: "
            + ", ".join(list(dropped)[:10])
        )
    ranked = sorted(models.values(), key=lambda r: r.num_reg_images(), reverse=True)
    res = MappingResult(
        ranked[0], "scratch", len(ranked), dropped_photos(db_path, names, ranked, cfg)
    )
    res.mapper = "global"
    refine_globally(res, db_path, image_root, work, cfg, names, fix_focal, frozenset())
    res.seconds = time.perf_counter() - t0
    return res


def refine_globally(
    res: MappingResult,
    db_path: Path,
    image_root: Path,
    work: Path,
    cfg: SfmConfig,
    names: list[str],
    fix_focal: bool,
    kept_previous: frozenset[str],
) -> None:
    """The global refinement of ``res.reconstruction`` (replaced): every track
    re-triangulated from the database (``cfg.retriangulate``), then the robust bundle
    adjustment of the whole model (``cfg.refine_iterations``; its stats into
    ``res.refinement``), the poses of ``kept_previous`` held."""
    if cfg.retriangulate:
        res.reconstruction = _retriangulate(
            res.reconstruction, db_path, image_root, work, cfg, names, fix_focal
        )
    if cfg.refine_iterations > 0:
        res.refinement = _refine(res.reconstruction, cfg, fix_focal, kept_previous)


def _continue(
    db_path: Path,
    image_root: Path,
    work: Path,
    cfg: SfmConfig,
    names: list[str],
    previous: pycolmap.Reconstruction,
    fix_focal: bool,
) -> tuple[dict[int, pycolmap.Reconstruction], str]:
    """Map continuing from ``previous`` (its photos outside ``names`` removed).

    Returns:
        The models and the mode: ``incremental``, or no models and ``incremental->scratch``
        when fewer than ``cfg.min_registered_share`` of the photos registered.
    """
    prev = pycolmap.Reconstruction(previous)
    keep = set(names)
    for iid in list(prev.reg_image_ids()):
        if prev.image(iid).name not in keep:
            prev.deregister_frame(prev.image(iid).frame_id)
    try:
        models = _run(db_path, image_root, work, cfg, names, prev, fix_focal)
    except Exception as exc:  # pycolmap raises RuntimeError/ValueError on bad input
        log.warning("incremental mapping from the previous model failed (%s)", exc)
        models = {}
    best = max(models.values(), key=lambda r: r.num_reg_images(), default=None)
    if best is None or best.num_reg_images() < cfg.min_registered_share * len(names):
        log.warning(
            "incremental mapping registered %d of %d photos: mapping from scratch",
            0 if best is None else best.num_reg_images(),
            len(names),
        )
        return {}, "incremental->scratch"
    return models, "incremental"


def dropped_photos(
    db_path: Path, names: list[str], ranked: list[pycolmap.Reconstruction], cfg: SfmConfig
) -> dict[str, str]:
    """Why each photo is not in the largest model ``ranked[0]``; warns when mapping split."""
    best = ranked[0]
    kept = {best.image(i).name for i in best.reg_image_ids()}
    others = {r.image(i).name for r in ranked[1:] for i in r.reg_image_ids()} - kept
    dropped = _reasons(db_path, names, kept, others, cfg)
    if len(ranked) > 1:
        log.warning(
            "mapping split into %d models (%s photos); keeping the largest",
            len(ranked),
            "/".join(str(r.num_reg_images()) for r in ranked),
        )
    return dropped


def _retriangulate(
    best: pycolmap.Reconstruction,
    db_path: Path,
    image_root: Path,
    work: Path,
    cfg: SfmConfig,
    names: list[str],
    fix_focal: bool,
) -> pycolmap.Reconstruction:
    """The model with every track re-triangulated from the database."""
    # Re-triangulate every track from the database with the registered poses:
    # incremental mapping leaves tracks split and pruned for intermediate geometry (and
    # a previous round's model keeps its own deformations in its tracks); full tracks
    # let the final refinement straighten the model (pycolmap's point triangulator).
    t1 = time.perf_counter()
    tri_dir = work / "retriangulated"
    tri_dir.mkdir(parents=True, exist_ok=True)
    best = pycolmap.triangulate_points(
        best,
        str(db_path),
        str(image_root),
        str(tri_dir),
        clear_points=True,
        options=mapping_options(cfg, names, fix_focal=fix_focal),
        refine_intrinsics=not fix_focal,
    )
    log.info("re-triangulated the model in %.1f s", time.perf_counter() - t1)
    return best


def _refine(
    best: pycolmap.Reconstruction,
    cfg: SfmConfig,
    fix_focal: bool,
    kept_previous: frozenset[str],
) -> dict:
    """The final robust refinement of ``best`` (:func:`robust_refinement`); its stats."""
    t1 = time.perf_counter()
    refinement = robust_refinement(
        best,
        cfg.refine_max_error_px,
        cfg.refine_iterations,
        cfg.num_threads,
        relax_first=False,
        refine_focal_length=not fix_focal,
        refine_extra_params=cfg.refine_distortion,
        constant_names=kept_previous,
    )
    refinement["seconds"] = time.perf_counter() - t1
    refinement["fixed_previous_photos"] = len(kept_previous)
    return refinement
