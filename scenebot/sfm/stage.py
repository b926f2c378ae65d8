"""The sfm stage: ``run(cfg, inputs, outputs)``.

Round r: a COLMAP model of ALL photos of rounds 0..r in the robot frame, written to
``results/{scene}/round_{r}/sfm/`` with ``point_descriptors.npz``, ``report.json``,
``accuracy.json`` (+ ``accuracy.png``) and ``map.png``. Features and matches live in one
persistent database per scene (``results/{scene}/sfm_db/database.db`` in the workflow), so a
round extracts features only of its new photos and matches only new pairs. Round r > 0
registers its new photos into round r-1's model (``inputs.previous_model``,
:mod:`scenebot.sfm.register`) and refines the whole map only when the new photos' residuals
or the robot's localization fixes say so; when too few register, COLMAP's incremental mapper
continues from the model, with a from-scratch fallback.

With the camera's lever arm (``cfg.camera_offset_m``) the metric scale comes from the circles
of photos turned in place, and a final bundle adjustment holds every circle photo on its
circle (``scenebot.sfm.circles``); photos whose EXIF gives the sensor-exact focal length
keep it fixed (``cfg.fix_exif_focal``).
"""

from __future__ import annotations

import json
import logging
import math
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pycolmap

from scenebot.sfm.align import Alignment, align_to_robot_frame, robot_frame_transform
from scenebot.sfm.circles import repair_circles
from scenebot.sfm.config import SfmConfig
from scenebot.sfm.descriptors import collect_point_descriptors, write_point_descriptors
from scenebot.sfm.evaluate import evaluate_accuracy
from scenebot.sfm.features import check_database_photos, extract, match_pairs, open_database
from scenebot.sfm.mapping import (
    MappingResult,
    SfmError,
    map_globally,
    map_photos,
    mapping_options,
    refine_globally,
)
from scenebot.sfm.orientation import drop_pairs_against_orientation
from scenebot.sfm.pairs import PairPrior, select_pairs
from scenebot.sfm.person_check import (
    TURNED_SHARE_NO_GLOBAL,
    PersonCheck,
    check_person_map,
    pairs_per_photo,
)
from scenebot.sfm.person_frame import person_frame_transform
from scenebot.sfm.photos import (
    Photo,
    check_photos,
    logged_known_distance,
    photos_from_captures,
    photos_from_folder,
)
from scenebot.sfm.place import (
    place_left_out_photos,
    robot_priors,
    robot_source,
    tracked_source,
)
from scenebot.sfm.register import (
    camera_xy,
    global_refinement_checks,
    map_new_photos,
    shot_poses,
)
from scenebot.sfm.tracked import (
    drop_off_tracking,
    map_from_motion,
    pairs_the_tracking_disowns,
    tracked_priors,
    tracked_residuals,
    tracked_session,
)

log = logging.getLogger(__name__)

MODEL_FILES = ("cameras.bin", "images.bin", "points3D.bin")


@dataclass
class SfmInputs:
    """Inputs of the sfm stage.

    Attributes:
        database: the scene's persistent COLMAP database (created if missing), e.g.
            ``results/{scene}/sfm_db/database.db``.
        capture_dirs: ``round_{k}/capture`` folders of rounds 0..r, in order (robot rounds).
        photo_folder: bring-your-own photos (``robot: photos``) instead of capture folders.
        previous_model: round r-1's ``sfm`` folder to continue from, or ``None``.
        shots_json: a guided round's shots: round r-1's ``goals.json`` (in ``previous_model``'s
            frame), where the person's new photos were meant to be taken
            (``sfm.person_shot_distance_m``), or ``None``.
    """

    database: Path
    capture_dirs: list[Path] = field(default_factory=list)
    photo_folder: Path | None = None
    previous_model: Path | None = None
    shots_json: Path | None = None


@dataclass
class SfmOutputs:
    """Outputs: ``model_dir`` receives the model, descriptors, report, accuracy and plots."""

    model_dir: Path

    @property
    def descriptors(self) -> Path:
        return self.model_dir / "point_descriptors.npz"

    @property
    def report(self) -> Path:
        return self.model_dir / "report.json"

    @property
    def accuracy(self) -> Path:
        return self.model_dir / "accuracy.json"

    @property
    def accuracy_png(self) -> Path:
        return self.model_dir / "accuracy.png"

    @property
    def map_png(self) -> Path:
        return self.model_dir / "map.png"


TRACKED_OUTLIER_SIGMAS = 3.0
"""A person's photo registered farther than this many ``sfm.motion_prior_std_m`` from where
its tracked motion puts it is misregistered (:func:`_drop_off_tracking`)."""


def inputs_for_round(
    scene_dir: Path, round_index: int, photo_folder: Path | None = None
) -> tuple[SfmInputs, SfmOutputs]:
    """The workflow's standard inputs and outputs of round ``round_index``.

    Layout: ``scene_dir/round_{k:03d}/capture`` for k = 0..r, the database
    ``scene_dir/sfm_db/database.db``, round r-1's model ``scene_dir/round_{r-1:03d}/sfm``
    (used when it exists), output ``scene_dir/round_{r:03d}/sfm``. With ``photo_folder``
    (``robot: photos``), round 0 is made from that folder.
    """
    scene_dir = Path(scene_dir)
    prev = scene_dir / f"round_{round_index - 1:03d}" / "sfm"
    inputs = SfmInputs(
        database=scene_dir / "sfm_db" / "database.db",
        capture_dirs=[scene_dir / f"round_{k:03d}" / "capture" for k in range(round_index + 1)]
        if photo_folder is None
        else [],
        photo_folder=photo_folder,
        previous_model=prev if round_index > 0 and (prev / "images.bin").exists() else None,
    )
    return inputs, SfmOutputs(scene_dir / f"round_{round_index:03d}" / "sfm")


def _priors(photos: list[Photo], previous: pycolmap.Reconstruction | None) -> list[PairPrior]:
    prev = {}
    if previous is not None:
        for iid in previous.reg_image_ids():
            im = previous.image(iid)
            v = im.cam_from_world().rotation.matrix()[2]
            prev[im.name] = (im.projection_center()[:2], math.atan2(v[1], v[0]))
    out = []
    for p in photos:
        heading = None
        if p.compass_deg is not None:
            heading = math.radians(p.compass_deg)
        elif p.odometry is not None:
            heading = p.odometry[2]
        frame, xy = None, None
        if p.name in prev:
            frame, xy, heading = "robot", tuple(prev[p.name][0]), prev[p.name][1]
        elif p.localization is not None:
            frame, xy = "robot", p.localization[:2]
            heading = p.localization[2] if heading is None else heading
        elif p.odometry is not None:
            frame, xy = f"odometry_{p.round}", p.odometry[:2]
        out.append(PairPrior(p.name, p.round, p.index, frame, xy, heading))
    return out


def _usable_previous(
    previous: pycolmap.Reconstruction | None, db_path: Path
) -> pycolmap.Reconstruction | None:
    """``previous`` if its image ids are those of the database, else ``None`` (logged)."""
    if previous is None:
        return None
    if not Path(db_path).exists():
        log.warning("no database %s: mapping from scratch, not from the previous model", db_path)
        return None
    with open_database(db_path) as db:
        for iid in previous.reg_image_ids():
            im = db.read_image_with_name(previous.image(iid).name)
            if im is None or im.image_id != iid:
                log.warning(
                    "previous model and database %s disagree on %s: mapping from scratch",
                    db_path,
                    previous.image(iid).name,
                )
                return None
    return previous


def _delete_loose_points(rec: pycolmap.Reconstruction) -> None:
    """Delete the 3D points seen by fewer than two registered photos."""
    for pid in list(rec.point3D_ids()):
        if rec.point3D(pid).track.length() < 2:
            rec.delete_point3D(pid)


def drop_misplaced(
    rec: pycolmap.Reconstruction,
    photos: list[Photo],
    camera_offset_m,
    max_deviation_m: float,
) -> dict[str, float]:
    """Deregister photos whose registered camera centre lies farther than ``max_deviation_m``
    from where the robot itself estimated the photo was taken (its ``localization`` in the
    log: a visual fix or odometry carried from one, map frame). Repeated textures can
    register a photo confidently at the wrong place; the robot's estimate is independent
    evidence. Photos without an estimate (round 0, bring-your-own) are not checked.

    Args:
        rec: the model, already in the robot frame (modified).
        photos: the photo set.
        camera_offset_m: camera centre (forward, left) in the robot frame (m), or None.
        max_deviation_m: the allowed distance (m); 0 or less turns the check off.

    Returns:
        Name -> deviation (m) of the photos taken out.
    """
    if max_deviation_m <= 0:
        return {}
    by_name = {rec.image(i).name: i for i in rec.reg_image_ids()}
    out: dict[str, float] = {}
    for p in photos:
        iid = by_name.get(p.name)
        if iid is None or p.localization is None:
            continue
        expect = camera_xy(p.localization, camera_offset_m)
        d = float(np.linalg.norm(rec.image(iid).projection_center()[:2] - expect))
        if d > max_deviation_m:
            rec.deregister_frame(rec.image(iid).frame_id)
            out[p.name] = d
    if out:
        _delete_loose_points(rec)
    return out


def drop_off_compass(
    rec: pycolmap.Reconstruction,
    photos: list[Photo],
    max_deviation_deg: float,
    camera_yaw_deg: float,
) -> dict[str, float]:
    """Deregister photos whose registered heading differs from their compass reading by more
    than ``max_deviation_deg``. The map's x axis is compass heading 0 (a robust fit over all
    photos, :mod:`scenebot.sfm.align`), so a photo's heading and its compass agree within
    the compass noise; a run of photos registered with a wrong rotation (a scratch mapping
    of the office once put part of a circle 20-30 deg and decimetres off) does not, and its
    position is wrong too. Photos without a compass reading are not checked.

    Args:
        rec: the model, already in the robot frame (modified).
        photos: the photo set.
        max_deviation_deg: the allowed difference (deg); 0 or less turns the check off.
        camera_yaw_deg: yaw of the camera's optical axis relative to the robot's forward
            axis (deg).

    Returns:
        Name -> heading difference (deg) of the photos taken out.
    """
    if max_deviation_deg <= 0:
        return {}
    by_name = {rec.image(i).name: i for i in rec.reg_image_ids()}
    out: dict[str, float] = {}
    for p in photos:
        iid = by_name.get(p.name)
        if iid is None or p.compass_deg is None or not math.isfinite(p.compass_deg):
            continue
        view = rec.image(iid).cam_from_world().rotation.matrix()[2]  # optical axis, world
        heading = math.degrees(math.atan2(view[1], view[0])) - camera_yaw_deg
        d = abs((heading - p.compass_deg + 180.0) % 360.0 - 180.0)
        if d > max_deviation_deg:
            rec.deregister_frame(rec.image(iid).frame_id)
            out[p.name] = d
    if out:
        _delete_loose_points(rec)
    return out


def circle_disagreement(alignment: Alignment) -> float | None:
    """How badly the turn-in-place circles disagree with the map: their scale spread
    (:func:`circle_scale_spread`), or infinity when two or more circles were long enough to
    check but the map left their photos off any circle (each rejected for its residual) and
    fewer than two remain (a map folded by repeating texture: the robot turned in place, the
    map says it did not; a generated room's round 0 came out so with its circles 32-167 % of
    their radius off, and the scale then fell back to odometry, 30 % off); None when there is
    nothing to judge by."""
    spread = circle_scale_spread(alignment)
    if spread is not None:
        return spread
    circles = alignment.stats.get("circles", [])
    off = sum(bool(c.get("off_circle")) for c in circles)
    used = sum(bool(c.get("used")) for c in circles)
    return math.inf if off >= 2 and used < 2 else None


def circle_scale_spread(alignment: Alignment) -> float | None:
    """How far apart the metric scales of the turn-in-place circles, each fitted on its
    own, lie: (max - min) / mean over the circles the lever-arm scale used; ``None`` when
    the scale does not come from two or more circles."""
    if alignment.scale_source != "camera_lever_arm":
        return None
    scales = [c["scale"] for c in alignment.stats.get("circles", []) if c.get("used")]
    if len(scales) < 2:
        return None
    return float(np.ptp(scales) / np.mean(scales))


@dataclass
class _Session:
    """What the steps of one run of the stage share.

    Attributes:
        cfg: sfm settings.
        db_path: the scene database; ``work``: its scratch folder (removed at the end).
        root, photos, names: the photo folder, the photo set and its names.
        previous: round r-1's model to continue from, or None.
        fix_focal: focal lengths held at their EXIF value.
        person: the photos are a person's (a photo folder, or the capture rounds of
            ``robot: guided`` and ``person-sim``): the person's frame
            (:mod:`scenebot.sfm.person_frame`) instead of the robot's.
        capture_dirs: the capture folders read (their logs may hold a person's tape
            measurement: :func:`~scenebot.sfm.photos.logged_known_distance`).
        timings: seconds per step (report.json ``timings_s``).
        shots: a guided round's shots, cam_from_world in ``previous``'s frame.
    """

    cfg: SfmConfig
    db_path: Path
    work: Path
    root: Path
    photos: list[Photo]
    names: list[str]
    previous: pycolmap.Reconstruction | None = None
    fix_focal: bool = False
    person: bool = False
    timings: dict[str, float] = field(default_factory=dict)
    capture_dirs: list[Path] = field(default_factory=list)
    shots: list[pycolmap.Rigid3d] = field(default_factory=list)


def _remap_while_circles_disagree(
    s: _Session,
    mres: MappingResult,
    alignment: Alignment,
    known: tuple[str, str, float] | None,
    align_kw: dict,
) -> tuple[MappingResult, Alignment, list[dict]]:
    """Map again from scratch with other seeds while the circles of photos turned in place
    disagree on the metric scale by more than ``cfg.max_circle_scale_spread`` (a bent map:
    runs of a circle misregistered bend its radius, and the lever-arm scale with it), or the
    map keeps no two of them on a circle (:func:`circle_disagreement`: folded), at most
    ``cfg.scale_remap_attempts`` times; keep the map whose circles agree best among those
    that register as many photos as the first (within 2 %). Maps continued from the
    previous round are not re-run (their scale is the previous round's).

    Returns:
        The kept mapping result and its alignment (model not yet moved), and one record per
        mapping run checked: seed, photos registered, circle scale spread, seconds, kept.
    """
    cfg = s.cfg
    spread = circle_disagreement(alignment)
    if spread is None or mres.continued:
        return mres, alignment, []
    first_seed = cfg.random_seed + max(mres.attempts, 1) - 1
    runs = [
        {
            "seed": first_seed,
            "registered": mres.reconstruction.num_reg_images(),
            "circle_scale_spread": _finite(spread),
            "circles_off": math.isinf(spread),
            "seconds": mres.seconds,
        }
    ]
    best = (spread, mres, alignment, 0)
    n_first = mres.reconstruction.num_reg_images()
    for k in range(cfg.scale_remap_attempts):
        if best[0] <= cfg.max_circle_scale_spread:
            break
        seed = cfg.random_seed + cfg.mapping_attempts + k
        _log_remap(cfg, best[0], seed, k)
        run_cfg = cfg.model_copy(update={"random_seed": seed, "mapping_attempts": 1})
        try:
            m2 = map_photos(
                s.db_path, s.root, s.names, s.work / f"remap_{k}", run_cfg,
                fix_focal=s.fix_focal, person_photos=s.person,
            )  # fmt: skip
            a2 = robot_frame_transform(
                m2.reconstruction, s.photos, known_distance=known, **align_kw
            )
        except (SfmError, ValueError) as exc:
            log.warning("mapping again with seed %d failed: %s", seed, exc)
            runs.append({"seed": seed, "failed": str(exc)})
            continue
        s2 = circle_disagreement(a2)
        n2 = m2.reconstruction.num_reg_images()
        runs.append(
            {
                "seed": seed,
                "registered": n2,
                "circle_scale_spread": _finite(s2),
                "circles_off": s2 is not None and math.isinf(s2),
                "seconds": m2.seconds,
            }
        )
        if s2 is not None and s2 < best[0] and n2 >= 0.98 * n_first:
            best = (s2, m2, a2, len(runs) - 1)
    for i, r in enumerate(runs):
        r["kept"] = i == best[3]
    if len(runs) > 1:
        log.info(
            "kept mapping run with seed %d: circle scale spread %s",
            runs[best[3]]["seed"],
            _spread_text(best[0]),
        )
    return best[1], best[2], runs


def _finite(x: float | None) -> float | None:
    """``x`` for report.json (None for infinity: JSON has none)."""
    return None if x is None or math.isinf(x) else x


def _spread_text(spread: float) -> str:
    return "none (no two circles on a circle)" if math.isinf(spread) else f"{100 * spread:.1f} %"


def _log_remap(cfg: SfmConfig, spread: float, seed: int, k: int) -> None:
    """Warn that the map is bent and mapping runs again (attempt ``k``, from 0)."""
    why = (
        "the map keeps no two circles of photos turned in place on a circle: it is folded"
        if math.isinf(spread)
        else f"the circles of photos turned in place disagree on the metric scale by "
        f"{100 * spread:.1f} % (sfm.max_circle_scale_spread = "
        f"{100 * cfg.max_circle_scale_spread:.1f} %): the map is bent"
    )
    log.warning(
        "%s; mapping again from scratch with seed %d (%d of sfm.scale_remap_attempts = %d)",
        why,
        seed,
        k + 1,
        cfg.scale_remap_attempts,
    )


def write_model(rec: pycolmap.Reconstruction, model_dir: Path) -> None:
    """Write ``rec`` as a COLMAP binary model into ``model_dir`` (created)."""
    model_dir.mkdir(parents=True, exist_ok=True)
    rec.write_binary(str(model_dir))


def run(cfg: SfmConfig, inputs: SfmInputs, outputs: SfmOutputs, person: bool = False) -> dict:
    """Run structure from motion on all photos of the inputs.

    Args:
        cfg: sfm settings.
        inputs: database, capture folders (or a photo folder), previous round's model.
        outputs: where to write.
        person: the capture folders hold a person's photos (``robot: guided``,
            ``person-sim``): the person's frame, as for a photo folder.

    Returns:
        The report (also written to ``report.json``): counts, dropped photos with reasons,
        pair counts, timings (s), alignment, ``scale`` (the source used, the lever-arm and
        odometry estimates and their relative difference, per-circle fits),
        ``circle_priors`` (photos moved back onto their circle, residuals), accuracy summary,
        ``global_refinement`` (round updates registered into the previous map: the checks,
        whether and why the whole map was refined), ``mapper`` and ``global_sfm`` (whether
        global SfM mapped a photo folder, and why), ``warnings`` (a person's photos: scale
        unknown, up uncertain).

    Raises:
        PhotoError: fewer than 3 photos, corrupt or truncated JPEGs (named).
        SfmError: fewer than ``cfg.min_registered_share`` of the photos registered (named),
            in a later round only when the map lost the previous map's photos too
            (:func:`_check_registered`).
    """
    t_start = time.perf_counter()
    unchanged = _round_without_photos(inputs, outputs)
    if unchanged is not None:
        return unchanged
    s = _open_session(cfg, inputs, person)
    features, pairs = _features_and_pairs(s)
    orientation = _drop_pairs_against_orientation(s)
    s.fix_focal = _focal_fixed(cfg, s.photos)
    mres = _map(s)
    if s.person:
        _drop_off_tracking(s, mres.reconstruction, mres.dropped)
    short_round = _check_registered(cfg, mres, len(s.photos), s.previous)

    mres, alignment, scale_checks = _align(s, mres)
    person_check: dict = {}
    if s.person:
        mres, alignment, person_check = _check_person_map(s, mres, alignment)
    _log_not_in_map(mres.dropped)
    t = time.perf_counter()
    align_to_robot_frame(mres.reconstruction, alignment)
    s.timings["align"] += time.perf_counter() - t
    first = alignment  # the metric scale found on the mapped model (report.json "scale")
    total_scale = alignment.scale
    checks, realigned = _refine_globally_if_needed(s, mres, alignment)
    if realigned is not None:
        alignment = realigned
        total_scale *= alignment.scale
    rec = mres.reconstruction
    _drop_inconsistent_photos(s, rec, alignment, mres.dropped)
    rec, on_circles, circle_stats = _hold_photos_on_circles(s, rec, alignment, mres.continued)
    if on_circles is not None:
        alignment = on_circles
        total_scale *= alignment.scale
    placed = _place_left_out(s, rec, alignment, mres.dropped)

    _replace_model(rec, Path(outputs.model_dir))
    t = time.perf_counter()
    write_point_descriptors(outputs.descriptors, collect_point_descriptors(rec, s.db_path))
    s.timings["descriptors"] = time.perf_counter() - t
    acc = _write_accuracy(cfg, rec, s.photos, outputs)
    s.timings["total"] = time.perf_counter() - t_start
    scale = _scale_report(first, total_scale, scale_checks)
    report = _report(s, rec, mres, features, pairs, circle_stats, scale, alignment, acc)
    report["global_refinement"] = checks
    report["placed"] = placed
    report["short_round"] = short_round
    if s.person:
        report["person_check"] = person_check
    if orientation is not None:
        report["orientation_pairs"] = orientation
    outputs.report.write_text(json.dumps(report, indent=1, default=_json_default))
    shutil.rmtree(s.work, ignore_errors=True)
    return report


def _round_without_photos(inputs: SfmInputs, outputs: SfmOutputs) -> dict | None:
    """A round that took no photo (a person who could take none of the shots: the capture
    log's ``shots_skipped``) leaves the map as it was: the previous round's model, its
    descriptors, pictures and report are this round's (report.json ``unchanged_from``),
    without mapping again. None when the round took photos, or without a previous model."""
    from scenebot.capturelog import photo_records

    if inputs.previous_model is None or not inputs.capture_dirs:
        return None
    log_path = Path(inputs.capture_dirs[-1]) / "log.jsonl"
    if not log_path.is_file() or photo_records(log_path):
        return None
    prev, out = Path(inputs.previous_model), Path(outputs.model_dir)
    _check_previous(prev)
    out.mkdir(parents=True, exist_ok=True)
    for f in out.glob("*.bin"):
        f.unlink()
    for f in prev.iterdir():
        if f.is_file():
            shutil.copyfile(f, out / f.name)
    report = json.loads((prev / "report.json").read_text(encoding="utf-8"))
    report["unchanged_from"] = prev.parent.name
    report["timings_s"] = {}
    outputs.report.write_text(json.dumps(report, indent=1, default=_json_default))
    log.warning("%s took no photo: the map is %s's, unchanged", log_path.parent.parent.name,
                prev.parent.name)  # fmt: skip
    return report


def _open_session(cfg: SfmConfig, inputs: SfmInputs, person: bool = False) -> _Session:
    """Read and check the photos and the previous round's model (if usable)."""
    timings: dict[str, float] = {}
    if inputs.photo_folder is not None:
        root, photos = photos_from_folder(inputs.photo_folder)
    else:
        if not inputs.capture_dirs:
            raise SfmError("sfm needs capture folders or a photo folder (robot: photos)")
        root, photos = photos_from_captures(inputs.capture_dirs)
    t = time.perf_counter()
    check_photos(photos, cfg.fallback_focal_factor)
    timings["check_photos"] = time.perf_counter() - t

    db_path = Path(inputs.database)
    previous = _read_previous(inputs.previous_model)
    if check_database_photos(db_path, photos) and previous is not None:
        log.warning(
            "database reset: mapping from scratch instead of from %s",
            Path(inputs.previous_model),
        )
        previous = None
    return _Session(
        cfg,
        db_path,
        db_path.parent / "work",
        root,
        photos,
        [p.name for p in photos],
        previous=_usable_previous(previous, db_path),
        person=inputs.photo_folder is not None or person,
        timings=timings,
        capture_dirs=[Path(d) for d in inputs.capture_dirs],
        shots=_read_shots(inputs.shots_json) if previous is not None else [],
    )


def _read_shots(shots_json: Path | None) -> list[pycolmap.Rigid3d]:
    """The shots of a guided round's guide (``goals.json``; none given: none)."""
    if shots_json is None:
        return []
    try:
        goals = json.loads(Path(shots_json).read_text(encoding="utf-8")).get("goals", [])
        return shot_poses(goals)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise SfmError(
            f"{shots_json}: cannot read the guide's shots ({exc}); run the previous round's "
            "goals stage again"
        ) from exc


def _read_previous(previous_model: Path | None) -> pycolmap.Reconstruction | None:
    """Round r-1's model from its folder (None: none given); SfmError without model files."""
    if previous_model is None:
        return None
    prev_dir = Path(previous_model)
    _check_previous(prev_dir)
    return pycolmap.Reconstruction(str(prev_dir))


def _check_previous(prev_dir: Path) -> None:
    """SfmError when round r-1's folder holds no COLMAP model."""
    if not all((prev_dir / f).is_file() for f in MODEL_FILES):
        raise SfmError(f"previous model {prev_dir} has no COLMAP model ({', '.join(MODEL_FILES)})")


def _features_and_pairs(s: _Session) -> tuple[dict, dict]:
    """Extract the new photos' features, select pairs and match the new ones.

    Returns:
        report.json's ``features`` (photo counts) and ``pairs`` (pair counts per kind).
    """
    cfg = s.cfg
    ext = extract(s.db_path, s.root, s.photos, cfg)
    s.timings["extract"] = ext["seconds"]
    log.info("features: %d new photos, %d reused", ext["new"], ext["reused"])

    pairs = select_pairs(
        _priors(s.photos, s.previous),
        exhaustive_max_images=cfg.exhaustive_max_images,
        spatial_neighbors=cfg.spatial_neighbors,
        spatial_max_distance_m=cfg.spatial_max_distance_m,
        sequential_overlap=cfg.sequential_overlap,
        loop_closure_pairs=cfg.loop_closure_pairs,
    )
    all_pairs = sorted(set().union(*pairs.values()))
    mt = match_pairs(s.db_path, all_pairs, cfg, s.work)
    s.timings["match"] = mt["seconds"]
    log.info("pairs: %d selected, %d newly matched", len(all_pairs), mt["new"])
    features = {k: ext[k] for k in ("new", "reused", "no_features")}
    return features, {k: len(v) for k, v in pairs.items()} | {"matched_now": mt["new"]}


def _drop_pairs_against_orientation(s: _Session) -> dict | None:
    """A person's photos with the camera's orientation or its tracked motion in their log:
    the verified pairs they contradict leave the database before mapping
    (:mod:`scenebot.sfm.orientation`); report.json's ``orientation_pairs``, None when no
    photo has either."""
    if not s.person or not any(p.orientation or p.motion for p in s.photos):
        return None
    cfg = s.cfg
    stats = drop_pairs_against_orientation(
        s.db_path, s.photos, cfg.orientation_max_deg, cfg.min_num_matches,
        cfg.motion_max_deg, cfg.motion_drift,
    )  # fmt: skip
    s.timings["orientation"] = stats["seconds"]
    if stats["dropped"]:
        log.info(
            "orientation: %d of %d verified pairs of photos with the camera's orientation "
            "contradict it by more than sfm.orientation_max_deg = %g deg: not used in mapping",
            stats["dropped"], stats["checked"], cfg.orientation_max_deg,
        )  # fmt: skip
    m = stats["motion"]
    if m["dropped"]:
        log.info(
            "motion: %d of %d verified pairs of photos with the camera's tracked motion point "
            "elsewhere than it by more than sfm.motion_max_deg = %g deg (plus the drift of "
            "sfm.motion_drift = %g per metre walked): not used in mapping",
            m["dropped"], m["checked"], cfg.motion_max_deg, cfg.motion_drift,
        )  # fmt: skip
    return stats


def _focal_fixed(cfg: SfmConfig, photos: list[Photo]) -> bool:
    """Whether the focal length stays at its EXIF value (``cfg.fix_exif_focal`` and every
    photo's EXIF gives the sensor-exact focal length); logs when it is refined instead."""
    fix_focal = cfg.fix_exif_focal and all(p.focal_source == "exif_focal_plane" for p in photos)
    if cfg.fix_exif_focal and not fix_focal:
        log.info(
            "focal length refined by bundle adjustment: not every photo's EXIF gives "
            "FocalLength and FocalPlaneResolution (sources: %s)",
            ", ".join(sorted({p.focal_source for p in photos})),
        )
    return fix_focal


def _map(s: _Session) -> MappingResult:
    """Map the photos: an adaptive round's new photos registered into the previous map
    (``cfg.register_new_photos``, :func:`map_new_photos`), else (or when too few register)
    :func:`map_photos`, continuing from the previous map with the photos the fast path
    registered."""
    cfg = s.cfg
    mres, start = None, s.previous
    if s.previous is not None and cfg.incremental and cfg.register_new_photos:
        mres, start = map_new_photos(
            s.db_path, s.root, s.photos, cfg, s.previous,
            None if s.person else _previous_camera_offset(s), shots=s.shots,
        )  # fmt: skip
    if mres is None and s.previous is None:
        mres = _map_tracked(s)
    if mres is None:
        mres = map_photos(
            s.db_path, s.root, s.names, s.work / "mapping", cfg, start, s.fix_focal,
            person_photos=s.person, held=s.previous,
        )  # fmt: skip
    s.timings["map"] = mres.seconds
    return mres


def _map_tracked(s: _Session) -> MappingResult | None:
    """A person's first map from the tracked motion (``cfg.motion_map``,
    :func:`map_from_motion`): the largest tracking session's photos placed at their tracked
    poses, the other photos then registered into it by the incremental mapper. None when
    off, not a person's photos, or no photo has a tracked pose."""
    cfg = s.cfg
    if not (s.person and cfg.motion_map):
        return None
    mres = map_from_motion(s.db_path, s.root, s.photos, cfg, s.fix_focal)
    if mres is None:
        return None
    rec = mres.reconstruction
    in_map = {rec.image(i).name for i in rec.reg_image_ids()}
    session = mres.refinement["session"]
    others = [p.name for p in s.photos if p.motion is None or p.motion.session != session]
    if not others:
        return mres
    log.info("registering %d photos of other sessions into the tracked map", len(others))
    tracked = mres
    mres = map_photos(
        s.db_path, s.root, s.names, s.work / "mapping", cfg, rec, s.fix_focal,
        person_photos=True, held=rec,
    )  # fmt: skip
    if mres.mode != "incremental":  # registering into it failed: the tracked map alone
        log.warning("the other sessions' photos did not register into the tracked map")
        tracked.dropped.update({n: "did not register into the tracked map" for n in others})
        return tracked
    mres.seconds += tracked.seconds
    mres.mapper = "tracked+incremental"
    mres.refinement = mres.refinement | {"tracked": tracked.refinement,
                                         "tracked_photos": len(in_map)}  # fmt: skip
    return mres


def _previous_camera_offset(s: _Session) -> tuple[float, float] | None:
    """The camera centre in the robot frame (forward, left) (m) as the alignment of the
    previous map finds it (None when it finds none)."""
    try:
        fit = robot_frame_transform(s.previous, s.photos, **_align_settings(s.cfg, None))
    except ValueError as exc:
        log.warning("no camera offset from the previous map (%s)", exc)
        return None
    return fit.camera_offset_m


def _refine_globally_if_needed(
    s: _Session, mres: MappingResult, alignment: Alignment
) -> tuple[dict, Alignment | None]:
    """After the fast path (mode ``registered``, model aligned): the global refinement
    (:func:`refine_globally`, mode ``registered+global``) when
    :func:`global_refinement_checks` ask for it, and the model aligned again.

    Returns:
        The checks (report.json ``global_refinement``; empty on other paths) and the new
        alignment (None when the refinement did not run).
    """
    if mres.mode != "registered":
        return {}, None
    cfg = s.cfg
    checks = global_refinement_checks(
        mres.reconstruction,
        mres.new_ids,
        mres.refinement.get("residual_ratio"),
        s.photos,
        alignment.camera_offset_m,
        cfg,
    )
    if not checks["run"]:
        return checks, None
    log.warning("global refinement of the map: %s", "; ".join(checks["reasons"]))
    t = time.perf_counter()
    registration = mres.refinement
    refine_globally(
        mres, s.db_path, s.root, s.work / "global", cfg, s.names, s.fix_focal,
        _kept_previous(s, True),
    )  # fmt: skip
    mres.refinement = mres.refinement | {"registration": registration}
    mres.mode = "registered+global"
    rec = mres.reconstruction
    alignment = robot_frame_transform(rec, s.photos, **_align_settings(cfg, s.previous))
    align_to_robot_frame(rec, alignment)
    checks["seconds"] = time.perf_counter() - t
    s.timings["global_refinement"] = checks["seconds"]
    return checks, alignment


def _check_registered(
    cfg: SfmConfig,
    mres: MappingResult,
    n_photos: int,
    previous: pycolmap.Reconstruction | None = None,
) -> dict | None:
    """SfmError naming the dropped photos when fewer than ``cfg.min_registered_share`` of
    the ``n_photos`` photos (or fewer than 3) registered (the fast path's photos taken out
    against the robot's estimate count as registered, as on the slow path, whose model
    holds them until the stage leaves them out: ``mres.overruled``).

    A round after the first (``previous``, round r-1's map) whose map still holds at least
    that share of the previous map's photos is not a broken map but a round whose new photos
    did not join it (repeating texture, a view the map never saw): the stage goes on with the
    map as it is and says so, and the goals stage's stuck rule (``goals.patience`` rounds that
    add no photo) stops a campaign that keeps failing so. Returns that case's figures
    (report.json ``short_round``), else None.
    """
    rec = mres.reconstruction
    n_reg = rec.num_reg_images()
    if n_reg + mres.overruled >= cfg.min_registered_share * n_photos and n_reg >= 3:
        return None
    listing = "\n  ".join(f"{n}: {why}" for n, why in list(mres.dropped.items())[:40])
    if previous is not None and n_reg >= 3:
        before = {previous.image(i).name for i in previous.reg_image_ids()}
        now = {rec.image(i).name for i in rec.reg_image_ids()}
        kept = len(before & now)
        if before and kept >= cfg.min_registered_share * len(before):
            short = {"photos": n_photos, "registered": n_reg, "overruled": mres.overruled,
                     "previous_map": len(before), "previous_kept": kept,
                     "joined": len(now - before),
                     "min_registered_share": cfg.min_registered_share}  # fmt: skip
            log.warning(
                "only %d of %d photos registered (sfm.min_registered_share = %g), but the map "
                "keeps %d of the previous map's %d photos: this round's photos did not join it "
                "(%d new photos in the map); going on with the map, the campaign stops as "
                "stuck after goals.patience such rounds. Dropped photos:\n  %s",
                n_reg, n_photos, cfg.min_registered_share, kept, len(before),
                short["joined"], listing,
            )  # fmt: skip
            return short
    raise SfmError(
        f"only {n_reg} of {n_photos} photos registered (sfm.min_registered_share = "
        f"{cfg.min_registered_share}; best of {max(mres.attempts, 1)} run(s), "
        f"sfm.mapping_attempts). Dropped photos:\n  {listing}\n"
        "Photos need overlap (neighbouring views sharing >= 1/3 of the scene) and "
        "texture; add photos between the dropped ones or lower sfm.min_registered_share."
    )


def _align_settings(cfg: SfmConfig, previous: pycolmap.Reconstruction | None) -> dict:
    """Keyword arguments of :func:`robot_frame_transform` from the settings."""
    return {
        "camera_yaw_deg": cfg.camera_yaw_deg,
        "use_compass": cfg.use_compass,
        "min_odometry_pairs": cfg.min_odometry_pairs,
        "previous": previous,
        "camera_offset_m": cfg.camera_offset_m,
        "min_circle_photos": cfg.min_circle_photos,
        "max_circle_residual": cfg.max_circle_residual,
    }


def _align(s: _Session, mres: MappingResult) -> tuple[MappingResult, Alignment, list[dict]]:
    """The robot-frame alignment of the mapped model, mapping again while its circles
    disagree on the scale (:func:`_remap_while_circles_disagree`; model not yet moved); a
    person's photos get the person's frame (:func:`person_frame_transform`)."""
    t = time.perf_counter()
    kd = s.cfg.known_distance
    align_kw = _align_settings(s.cfg, s.previous)
    known = (kd.image_a, kd.image_b, kd.distance_m) if kd else None
    if s.person:
        alignment = _person_alignment(s, mres)
        s.timings["align"] = time.perf_counter() - t
        return mres, alignment, []
    alignment = robot_frame_transform(
        mres.reconstruction, s.photos, known_distance=known, **align_kw
    )
    s.timings["align"] = time.perf_counter() - t
    mres, alignment, scale_checks = _remap_while_circles_disagree(
        s, mres, alignment, known, align_kw
    )
    s.timings["map"] += sum(c.get("seconds", 0.0) for c in scale_checks[1:])
    return mres, alignment, scale_checks


def _person_alignment(
    s: _Session, mres: MappingResult, standing_up: np.ndarray | None = None
) -> Alignment:
    """The person's frame of the mapped model (:func:`person_frame_transform`): the scale
    from ``sfm.known_distance`` or the logged tape, up from ``sfm.up_photo``, else from the
    standing photos' plane (``standing_up``, model frame), else estimated."""
    kd = s.cfg.known_distance
    known = (kd.image_a, kd.image_b, kd.distance_m) if kd else None
    up = s.cfg.up_photo
    tape = _person_known_distance(s, known)
    if tape is not None and known is None:  # the logged tape: its photos may not be in the map
        rec = mres.reconstruction
        registered = {rec.image(i).name for i in rec.reg_image_ids()}
        if not {tape[0], tape[1]} <= registered:
            log.warning(
                "the tape measured between %s and %s (the capture log's known_distance), "
                "not both in the map: the map's scale is unknown (set sfm.known_distance "
                "between two photos that registered)", tape[0], tape[1],
            )  # fmt: skip
            tape = None
    return person_frame_transform(
        mres.reconstruction,
        s.photos,
        known_distance=tape,
        up_photo=(_person_photo_name(s, up.image), up.side) if up else None,
        standing_up=standing_up,
    )


def _standing_photos(s: _Session) -> list[str]:
    """The photos taken standing at eye height: a guided campaign's round 0 (the walk around
    the room); none for a photo folder (``robot: photos``), whose heights are the person's."""
    return [p.name for p in s.photos if p.round == 0] if s.capture_dirs else []


def _person_check(s: _Session, mres: MappingResult, alignment: Alignment) -> PersonCheck:
    """:func:`check_person_map` of the mapped model (any frame) with its alignment."""
    metric = alignment.scale_source != "none"
    return check_person_map(
        mres.reconstruction,
        s.db_path,
        standing=_standing_photos(s),
        to_frame=(alignment.scale, alignment.R, alignment.t) if metric else None,
        min_pair_share=s.cfg.person_min_pair_share,
        height_std_m=s.cfg.person_height_std_m,
    )


def _unplaced(s: _Session, mres: MappingResult, check: PersonCheck) -> tuple[bool, bool, int, int]:
    """How wrong a map of the person's photos is, for choosing among maps of the same
    photos: failing its check, failing it as a whole (``check.whole``: no photo to leave
    out makes it right), then photos not registered or named by the check, then
    contradicted pairs (smaller is better)."""
    missing = len(s.photos) - mres.reconstruction.num_reg_images()
    named = missing + len(check.named_photos)
    return not check.ok, check.whole, named, len(check.contradicted)


def _person_remaps(s: _Session, check: PersonCheck, registered: int, mapper: str):
    """The other ways to map a person's photos (``mapper``: the first map's), in order: from
    the tracked motion (:func:`_map_tracked`, when some photos have it and the first map
    was not that), global SfM (not when at least
    :data:`TURNED_SHARE_NO_GLOBAL` of the ``registered`` photos turned in place, as ``check``
    of the first map finds them: ``map`` is then None), then incremental mapping from
    scratch with ``cfg.person_remap_attempts`` other seeds (without global SfM's fallback when
    it is not tried itself). Yields ``(how, map)`` with ``map()`` the mapping result."""
    cfg = s.cfg
    if cfg.motion_map and not mapper.startswith("tracked") and tracked_session(s.photos):
        yield "from the tracked motion", lambda: _map_tracked(s)
    turned = check.stats["pairs"].get("turned_in_place_photos", 0)
    no_global = turned >= TURNED_SHARE_NO_GLOBAL * registered
    if no_global:
        log.warning(
            "not mapping the person's photos with global SfM: %d of %d photos turned in "
            "place, which global positioning cannot place",
            turned,
            registered,
        )
        yield "global SfM", None
    else:
        yield (
            "global SfM",
            lambda: map_globally(
                s.db_path, s.root, s.names, s.work / "person_global", cfg, s.fix_focal
            ),
        )
    # the incremental re-mappings without their own global-SfM fallback where global SfM
    # cannot place the photos (it mapped the canned folder's circles 67% of the map's size off
    # the incremental model, and each re-mapping ran it again: 20-40 s each)
    for k in range(cfg.person_remap_attempts):
        seed = cfg.random_seed + cfg.mapping_attempts + k
        run_cfg = cfg.model_copy(update={"random_seed": seed, "mapping_attempts": 1})
        yield f"incremental, seed {seed}", lambda c=run_cfg, k=k: map_photos(
            s.db_path, s.root, s.names, s.work / f"person_remap_{k}", c,
            fix_focal=s.fix_focal, person_photos=not no_global,
        )  # fmt: skip


def _only_new_photos_named(s: _Session, mres: MappingResult, check: PersonCheck) -> bool:
    """Whether the check names only photos new this round, in a map that registered them
    into the previous round's (the fast path: the previous photos' poses held; that map
    passed its check), and does not fail the map as a whole: the new photos are what is
    wrong, and mapping everything again would risk the map that passed."""
    if s.previous is None or not mres.mode.startswith("registered") or check.whole:
        return False
    old = {s.previous.image(i).name for i in s.previous.reg_image_ids()}
    # a pair of an old and a new photo blames the new one; a pair of two old photos, both
    named = set(check.off_plane) | {
        n for a, b, *_ in check.contradicted for n in (a, b) if n not in old or {a, b} <= old
    }
    return bool(named) and not (named & old)


def _check_person_map(
    s: _Session, mres: MappingResult, alignment: Alignment
) -> tuple[MappingResult, Alignment, dict]:
    """Check a person's map without the truth (:mod:`scenebot.sfm.person_check`) and react:
    a map that fails is mapped again (:func:`_person_remaps`) until one passes, the least
    wrong one kept (:func:`_unplaced`); the photos its check still names are left out (off
    the eye-height plane first, then the photo in most contradicted pairs) while at least
    ``cfg.min_registered_share`` of the photos stay; a map still failing stops the stage
    with the check's reasons. The frame is then levelled by the standing photos' plane.

    Returns:
        The kept mapping result and its alignment (model not yet moved), and report.json's
        ``person_check``.

    Raises:
        SfmError: no map of the photos passes the check.
    """
    cfg = s.cfg
    if cfg.person_min_pair_share <= 0 and cfg.person_height_std_m <= 0:
        return mres, alignment, {"ok": None, "note": "off (sfm.person_min_pair_share and "
                                 "sfm.person_height_std_m are 0)"}  # fmt: skip
    t = time.perf_counter()
    check = _person_check(s, mres, alignment)
    runs = [_check_record("as mapped", mres, check)]
    if not check.ok and check.contradicted and cfg.motion_map and tracked_session(s.photos):
        check = _drop_disowned_pairs(s, mres, alignment, check, runs)
    best, kept = (mres, alignment, check), len(runs) - 1
    if not check.ok and _only_new_photos_named(s, mres, check):
        log.warning(
            "the person's map fails its check for new photos only (the previous map passed "
            "it and its poses were held): leaving them out, not mapping again: %s",
            "; ".join(check.problems),
        )
        runs.append({"mapping": "again", "skipped": "only new photos named"})
    elif not check.ok:
        log.warning("the person's map fails its check: %s", "; ".join(check.problems))
        registered = mres.reconstruction.num_reg_images()
        for how, remap in _person_remaps(s, check, registered, mres.mapper):
            if remap is None:
                runs.append({"mapping": how, "skipped": "photos turned in place"})
                continue
            log.warning("mapping the person's photos again: %s", how)
            try:
                m2 = remap()
                if m2 is None:
                    raise SfmError("no tracking session of three photos with features")
                _drop_off_tracking(s, m2.reconstruction, m2.dropped)
                a2 = _person_alignment(s, m2)
            except (SfmError, ValueError) as exc:
                log.warning("%s failed: %s", how, exc)
                runs.append({"mapping": how, "failed": str(exc)})
                continue
            s.timings["map"] += m2.seconds
            c2 = _person_check(s, m2, a2)
            runs.append(_check_record(how, m2, c2))
            if _unplaced(s, m2, c2) < _unplaced(s, best[0], best[2]):
                best, kept = (m2, a2, c2), len(runs) - 1
            if c2.ok:
                break
    mres, alignment, check = best
    for i, r in enumerate(runs):
        r["kept"] = i == kept
    left_out: dict[str, str] = {}
    if not check.ok:
        alignment, check = _leave_out_named(s, mres, alignment, check, left_out)
    if not check.ok:
        raise SfmError(_bent_message(check, runs))
    plane = check.stats.get("plane", {})
    if plane.get("checked") and plane.get("planar"):
        n_model = np.asarray(alignment.R).T @ np.asarray(plane["normal"])
        alignment = _person_alignment(s, mres, standing_up=n_model)
    report = check.as_dict() | {
        "mapping_runs": runs,
        "left_out": left_out,
        "seconds": time.perf_counter() - t,
    }
    return mres, alignment, report


def _drop_disowned_pairs(
    s: _Session, mres: MappingResult, alignment: Alignment, check: PersonCheck, runs: list
) -> PersonCheck:
    """A map of photos with a tracked motion that does not hold some verified pairs: the
    pairs whose two photos lie where their tracking puts them (within ``sfm.motion_prior_std_m``,
    :func:`pairs_the_tracking_disowns`) are wrong matches (a repeating texture), not photos
    registered off: they leave the database, as the pairs the sensors contradict do, and the
    map is checked again (``runs`` gets the line)."""
    residuals = tracked_residuals(mres.reconstruction, s.photos)
    wrong = pairs_the_tracking_disowns(check.contradicted, residuals, s.cfg.motion_prior_std_m)
    if not wrong:
        return check
    with open_database(s.db_path) as db:
        ids = {im.name: im.image_id for im in db.read_all_images()}
        for a, b in wrong:
            db.delete_two_view_geometry(ids[a], ids[b])
    log.warning(
        "%d of the %d verified pairs the map does not hold join photos that lie where "
        "their tracking puts them (within sfm.motion_prior_std_m = %g m): wrong matches, not "
        "used: %s", len(wrong), len(check.contradicted), s.cfg.motion_prior_std_m,
        ", ".join(f"{a.rsplit('/', 1)[-1]}-{b.rsplit('/', 1)[-1]}" for a, b in wrong[:8]),
    )  # fmt: skip
    check = _person_check(s, mres, alignment)
    runs.append(_check_record("the pairs the tracking disowns dropped", mres, check)
                | {"pairs_dropped": len(wrong)})  # fmt: skip
    return check


def _check_record(how: str, mres: MappingResult, check: PersonCheck) -> dict:
    """One mapping run's line in report.json ``person_check.mapping_runs``."""
    return {
        "mapping": how,
        "mapper": mres.mapper,
        "registered": mres.reconstruction.num_reg_images(),
        "ok": check.ok,
        "whole": check.whole,
        "median_pair_share": check.stats["pairs"].get("median_share"),
        "contradicted_pairs": len(check.contradicted),
        "off_plane": len(check.off_plane),
        "problems": check.problems,
    }


def _leave_out_named(
    s: _Session,
    mres: MappingResult,
    alignment: Alignment,
    check: PersonCheck,
    left_out: dict[str, str],
) -> tuple[Alignment, PersonCheck]:
    """Take the photos the check names out of the map, one step at a time (those off the
    eye-height plane, else the photo with the largest share of its verified pairs
    contradicted, ties: more contradicted pairs, then fewer 3D points seen), re-triangulating
    and refining the map and re-checking after each (a photo registered off drags the
    tracks of the right photos it shares points with: office, a guided round, a photo 1.3 m
    off left its right neighbour's pairs at 0-10 %), while at least
    ``cfg.min_registered_share`` of the photos stay registered and the scale's photos stay
    in; ``left_out`` (name -> reason) and ``mres.dropped`` receive them.

    Returns:
        The alignment and the check of the map without them.
    """
    floor = s.cfg.min_registered_share * len(s.photos)
    step = 0
    while not check.ok:
        rec = mres.reconstruction
        by_name = {rec.image(i).name: i for i in rec.reg_image_ids()}
        if check.off_plane:
            out = {
                n: f"registered {r:+.2f} m off the eye-height plane of the person's other "
                "standing photos (sfm.person_height_std_m)"
                for n, r in check.off_plane.items()
            }
        elif check.contradicted:
            count = pairs_per_photo(check.contradicted)
            checked = check.pairs_per_photo
            worst = max(
                count,
                key=lambda n: (
                    count[n] / max(checked.get(n, 1), 1),
                    count[n],
                    -rec.image(by_name[n]).num_points3D,
                ),
            )
            others = sorted({b if a == worst else a for a, b, *_ in check.contradicted
                             if worst in (a, b)})  # fmt: skip
            out = {
                worst: "its verified matches with "
                + ", ".join(n.rsplit("/", 1)[-1] for n in others)
                + " are not one 3D point in the map: registered off (sfm.person_min_pair_share)"
            }
        else:
            break  # the walk as a whole is bent: no photo to blame
        if rec.num_reg_images() - len(out) < floor:
            break
        for n, why in out.items():
            rec.deregister_frame(rec.image(by_name[n]).frame_id)
            left_out[n] = why
            mres.dropped[n] = why
        log.warning(
            "left out of the person's map: %s", "; ".join(f"{n} ({w})" for n, w in out.items())
        )
        spread = _camera_spread(rec)
        refine_globally(
            mres, s.db_path, s.root, s.work / f"person_left_out_{step}", s.cfg, s.names,
            s.fix_focal, _kept_previous(s, mres.continued),
        )  # fmt: skip
        _hold_camera_spread(mres.reconstruction, spread)
        step += 1
        try:
            alignment = _person_alignment(s, mres)
        except ValueError as exc:  # a photo of the scale left out
            check.problems.append(str(exc))
            break
        check = _person_check(s, mres, alignment)
    return alignment, check


def _camera_spread(rec: pycolmap.Reconstruction) -> float:
    """The median distance of the registered camera centres from their centroid (model
    units)."""
    C = np.array([rec.image(i).projection_center() for i in rec.reg_image_ids()])
    return float(np.median(np.linalg.norm(C - C.mean(0), axis=1)))


def _hold_camera_spread(rec: pycolmap.Reconstruction, spread: float) -> None:
    """Scale ``rec`` about its origin back to the camera spread ``spread``
    (:func:`_camera_spread`). Bundle adjustment leaves a map's scale free and a refinement
    moves it: the canned folder's map, whose scale nothing gives (SfM units), grew 4.3 times
    over the refinements of seven photos left out (its circles, 1 m apart, came 25-38 units
    apart, beyond mesh.max_point_range_m); each refinement of it alone moved it 4-23 %."""
    now = _camera_spread(rec)
    if now > 0 and spread > 0:
        rec.transform(pycolmap.Sim3d(spread / now, pycolmap.Rotation3d(), np.zeros(3)))


def _bent_message(check: PersonCheck, runs: list[dict]) -> str:
    """The stage's stop when no map of a person's photos passes its check."""
    tried = "; ".join(
        f"{r['mapping']}: "
        + ("failed" if "failed" in r else "skipped" if "skipped" in r else
           f"{r['contradicted_pairs']} contradicted pair(s), "
           f"{r['off_plane']} photo(s) off the plane")
        for r in runs
    )  # fmt: skip
    named = sorted(check.named_photos)
    where = ", ".join(n.rsplit("/", 1)[-1] for n in named[:12]) or "the whole walk"
    return (
        "the person's map is bent or has photos registered off, in every way it was mapped "
        f"({tried}): " + "; ".join(check.problems) + f". Near {where} the photos hold the map "
        "weakly: add photos there (closer together, of textured surfaces) and run again; "
        "report.json person_check has the pairs and heights (sfm.person_min_pair_share, "
        "sfm.person_height_std_m)"
    )


def _person_known_distance(
    s: _Session, known: tuple[str, str, float] | None
) -> tuple[str, str, float] | None:
    """A person's scale: ``sfm.known_distance`` (its photo names as the map has them, or as
    the person named them: a file of ``photos.folder`` taken in as ``round_000/capture/...``),
    else the tape measurement in the capture logs (``robot: person-sim``)."""
    if known is None:
        return logged_known_distance(s.capture_dirs) if s.capture_dirs else None
    a, b, d = known
    return _person_photo_name(s, a), _person_photo_name(s, b), d


def _person_photo_name(s: _Session, name: str) -> str:
    """A photo named in a setting as the map names it: a photo folder's file taken into a
    guided campaign's round 0 (``IMG_0001.jpg``) is ``round_000/capture/images/r000_...``."""
    if name in s.names:
        return name
    by_source = {Path(p.source).name: p.name for p in s.photos if p.source}
    return by_source.get(name, name)


def _log_not_in_map(dropped: dict[str, str]) -> None:
    """Warn about the photos mapping left out, with reasons."""
    if dropped:
        log.warning(
            "%d photo(s) not in the map: %s",
            len(dropped),
            "; ".join(f"{n} ({why})" for n, why in dropped.items()),
        )


def _drop_off_tracking(s: _Session, rec: pycolmap.Reconstruction, dropped: dict[str, str]) -> None:
    """A person's photos registered far from where their tracked motion puts them out of
    ``rec`` (:func:`~scenebot.sfm.tracked.drop_off_tracking`, beyond
    :data:`TRACKED_OUTLIER_SIGMAS` ``sfm.motion_prior_std_m``), logged and added to
    ``dropped``: before the person check (a photo registered one motif off contradicts
    the pairs of the photos it sees, and the check would map every photo again) and after
    the map's last change."""
    bound = TRACKED_OUTLIER_SIGMAS * s.cfg.motion_prior_std_m
    off = drop_off_tracking(rec, s.photos, bound)
    if not off:
        return
    _delete_loose_points(rec)
    log.warning(
        "%d photo(s) registered far from where their phone's tracked motion puts them "
        "(> %g x sfm.motion_prior_std_m = %.2f m; a repeating texture matched one motif "
        "off), left out of the map: %s",
        len(off), TRACKED_OUTLIER_SIGMAS, bound,
        ", ".join(f"{n} ({d:.2f} m)" for n, d in off.items()),
    )  # fmt: skip
    dropped.update(
        {n: f"registered {d:.2f} m from where its tracked motion puts it" for n, d in off.items()}
    )


def _drop_inconsistent_photos(
    s: _Session, rec: pycolmap.Reconstruction, alignment: Alignment, dropped: dict[str, str]
) -> None:
    """Take photos registered far from the robot's own estimate, from a person's tracked
    motion (:func:`~scenebot.sfm.tracked.drop_off_tracking`) or off their compass reading out
    of ``rec`` (aligned), logged and added to ``dropped`` with reasons."""
    cfg = s.cfg
    if s.person:
        _drop_off_tracking(s, rec, dropped)
    misplaced = drop_misplaced(
        rec, s.photos, alignment.camera_offset_m, cfg.max_estimate_deviation_m
    )
    if misplaced:
        log.warning(
            "%d photo(s) registered far from where the robot estimated it took them "
            "(> sfm.max_estimate_deviation_m = %.2f m), left out of the map: %s",
            len(misplaced),
            cfg.max_estimate_deviation_m,
            ", ".join(f"{n} ({d:.2f} m)" for n, d in misplaced.items()),
        )
        dropped.update(
            {n: f"registered {d:.2f} m from the robot's own estimate" for n, d in misplaced.items()}
        )
    if cfg.use_compass:
        turned = drop_off_compass(rec, s.photos, cfg.max_compass_deviation_deg, cfg.camera_yaw_deg)
        if turned:
            log.warning(
                "%d photo(s) registered with a heading far from their compass reading "
                "(> sfm.max_compass_deviation_deg = %g deg), left out of the map: %s",
                len(turned),
                cfg.max_compass_deviation_deg,
                ", ".join(f"{n} ({d:.0f} deg)" for n, d in turned.items()),
            )
            dropped.update(
                {n: f"registered {d:.0f} deg off its compass reading" for n, d in turned.items()}
            )


def _place_left_out(
    s: _Session, rec: pycolmap.Reconstruction, alignment: Alignment, dropped: dict[str, str]
) -> dict:
    """The photos left out placed at a prior pose and kept when the map confirms them
    (:func:`place_left_out_photos`): a robot's at its estimate (``cfg.place_left_out_photos``),
    a person's at their tracked motion (``cfg.place_tracked_photos``,
    :func:`~scenebot.sfm.tracked.tracked_priors`); report.json ``placed``."""
    on = s.cfg.place_tracked_photos if s.person else s.cfg.place_left_out_photos
    if not on or not dropped:
        return {}
    t = time.perf_counter()
    if s.person:
        priors, why = tracked_priors(rec, s.photos, set(dropped))
        source = tracked_source(s.cfg)
    else:
        priors, why = robot_priors(rec, s.photos, dropped, alignment.camera_offset_m, s.cfg), {}
        source = robot_source(s.cfg)
    placed = place_left_out_photos(rec, s.db_path, s.root, s.photos, dropped, priors, source,
                                   s.cfg)  # fmt: skip
    if why:
        placed["no_prior"] = why
    s.timings["place"] = time.perf_counter() - t
    return placed


def _kept_previous(s: _Session, continued: bool) -> frozenset[str]:
    """The previous round's photos, whose poses a round update holds
    (``cfg.update_keep_previous_poses``; none when the model was not continued)."""
    if not (continued and s.cfg.update_keep_previous_poses and s.previous is not None):
        return frozenset()
    return frozenset(s.previous.image(i).name for i in s.previous.reg_image_ids())


def _hold_photos_on_circles(
    s: _Session, rec: pycolmap.Reconstruction, alignment: Alignment, continued: bool
) -> tuple[pycolmap.Reconstruction, Alignment | None, dict]:
    """With the lever-arm scale and ``cfg.circle_prior_std_m``: repair and adjust the
    turn-in-place circles (:func:`repair_circles`) and align the result again.

    Returns:
        The model (aligned), the new alignment (None when not run) and the circle stats.
    """
    cfg = s.cfg
    kept_previous = _kept_previous(s, continued)
    if not (
        cfg.camera_offset_m is not None
        and cfg.circle_prior_std_m > 0
        and alignment.scale_source == "camera_lever_arm"
    ):
        return rec, None, {}
    t = time.perf_counter()
    rec, circle_stats = repair_circles(
        rec,
        s.photos,
        alignment.camera_offset_m,
        s.db_path,
        s.root,
        s.work / "circles",
        triangulation_options=mapping_options(cfg, s.names, fix_focal=s.fix_focal),
        max_residual_m=cfg.circle_max_residual_m,
        prior_std_m=cfg.circle_prior_std_m,
        iterations=cfg.circle_prior_iterations,
        min_photos=cfg.min_circle_photos,
        camera_yaw_deg=cfg.camera_yaw_deg,
        max_error_px=cfg.refine_max_error_px,
        refine_focal_length=not s.fix_focal,
        refine_extra_params=cfg.refine_distortion,
        num_threads=cfg.num_threads,
        constant_names=kept_previous,
    )
    alignment = robot_frame_transform(rec, s.photos, **_align_settings(cfg, s.previous))
    align_to_robot_frame(rec, alignment)
    s.timings["circle_priors"] = time.perf_counter() - t
    return rec, alignment, circle_stats


def _replace_model(rec: pycolmap.Reconstruction, model_dir: Path) -> None:
    """Write ``rec`` into ``model_dir``, removing an earlier run's model files first."""
    if model_dir.exists():
        for f in model_dir.glob("*.bin"):
            f.unlink()
    write_model(rec, model_dir)


def _write_accuracy(
    cfg: SfmConfig, rec: pycolmap.Reconstruction, photos: list[Photo], outputs: SfmOutputs
) -> dict:
    """Evaluate against the logged true poses (if any) into ``accuracy.json``, and write the
    plots (``cfg.plots``). Returns the accuracy."""
    truths = {p.name: p.truth for p in photos if p.truth}
    acc = (
        evaluate_accuracy(rec, truths)
        if truths
        else {"evaluated": 0, "note": "no true poses in the capture logs (real robot or photos)"}
    )
    outputs.accuracy.write_text(json.dumps(acc, indent=1))
    if cfg.plots:
        from scenebot.sfm.plots import plot_accuracy_histograms, plot_map

        plot_map(rec, outputs.map_png)
        plot_accuracy_histograms(acc, outputs.accuracy_png)
    return acc


def _report(
    s: _Session,
    rec: pycolmap.Reconstruction,
    mres: MappingResult,
    features: dict,
    pairs: dict,
    circle_stats: dict,
    scale: dict,
    alignment: Alignment,
    acc: dict,
) -> dict:
    """The content of report.json (see :func:`run`)."""
    return {
        "photos": len(s.photos),
        "registered": rec.num_reg_images(),
        "points3D": rec.num_points3D(),
        "mean_reprojection_error_px": rec.compute_mean_reprojection_error(),
        "mapping_mode": mres.mode,
        "mapping_attempts": mres.attempts,
        "mapper": mres.mapper,
        "global_sfm": mres.global_sfm,
        "refinement": mres.refinement,
        "circle_priors": circle_stats,
        "models": mres.num_models,
        "dropped": mres.dropped,
        "features": features,
        "pairs": pairs,
        "cameras": [
            {"camera_id": c.camera_id, "model": c.model_name, "params": list(c.params)}
            for c in rec.cameras.values()
        ],
        "focal_sources": sorted({p.focal_source for p in s.photos}),
        "focal_fixed": s.fix_focal,
        "scale": scale,
        "alignment": alignment.as_dict(),
        "warnings": alignment.stats.get("warnings", []),
        "timings_s": s.timings,
        "accuracy": _accuracy_summary(acc),
    }


def _scale_report(first: Alignment, total_scale: float, scale_checks: list[dict]) -> dict:
    """report.json's ``scale``: the scale found on the mapped model (``first``) and the
    total scale applied."""
    return {
        "source": first.scale_source,
        "m_per_sfm_unit": total_scale,
        "from_camera_lever_arm": first.stats.get("scale_circles"),
        "from_odometry": first.stats.get("scale_odometry"),
        "odometry_vs_lever_arm": first.stats.get("scale_odometry_vs_circles"),
        "circles_used": first.stats.get("circles_used", 0),
        "circles": first.stats.get("circles", []),
        "circle_scale_spread": circle_scale_spread(first),
        "mapping_runs_checked": scale_checks,
    }


def _accuracy_summary(acc: dict) -> dict:
    """report.json's ``accuracy``: the headline figures of ``accuracy.json``."""
    return {
        k: acc[k]
        for k in (
            "metric_scale_error",
            "position_error_m",
            "heading_error_deg",
            "frame_tilt_deg",
        )
        if k in acc
    }


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o).__name__)
