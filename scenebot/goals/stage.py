"""The goals stage's entry point: ``run(cfg, inputs, outputs)`` with the rule's paths."""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scenebot.artifacts import round_name
from scenebot.artifacts.candidates import read_candidates
from scenebot.artifacts.freespace import FreeSpace, FreeSpaceError
from scenebot.geometry import read_sparse_map
from scenebot.goals.config import GoalsConfig
from scenebot.goals.failures import (
    abandoned_goals,
    idle_rounds,
    near_abandoned,
    unfulfilled_shots,
)
from scenebot.goals.select import goals_document, same_view, select_goals, write_goals
from scenebot.goals.stopping import apply_stopping_rule, diminishing_returns

log = logging.getLogger(__name__)


@dataclass
class GoalsInputs:
    """Inputs of the goals stage."""

    candidates_csv: Path
    freespace_npz: Path
    sfm_dir: Path | None = None  # the map (camera poses); the frontier method needs it
    previous_goals_json: Path | None = None  # the previous round's (diminishing returns)
    previous_freespace_npz: Path | None = None  # the previous round's (its new free space)
    mesh_ply: Path | None = None  # the map's surface: a person's coverage picture needs it
    # the capture logs of the adaptive rounds so far (goals abandoned there are not chosen
    # again; rounds that added no photo make the campaign stuck: scenebot.goals.failures)
    capture_logs: list[Path] = field(default_factory=list)
    # a guided round's fulfilment.json: the shots no photo fulfilled, as a person's abandoned
    # goals (scenebot.guide.fulfil)
    fulfilment_json: Path | None = None


@dataclass
class GoalsOutputs:
    """Outputs: ``goals.json`` and an optional heat-map picture."""

    goals_json: Path
    goals_png: Path | None = None


def run(cfg: GoalsConfig, inputs: GoalsInputs, outputs: GoalsOutputs, person: bool = False) -> dict:
    """Choose the goals of the next round and decide whether exploration is complete.

    Args:
        cfg: goals settings.
        inputs: the round's candidates, free space and map.
        outputs: the files to write.
        person: the photos are a person's (``robot: photos``): six-degree-of-freedom goals in
            the 3-D free space (:func:`_person_goals`).

    Returns:
        The goals.json document.
    """
    where = round_name(inputs.candidates_csv, outputs.goals_json)
    cols = read_candidates(inputs.candidates_csv)
    poses = np.column_stack([cols["x"], cols["y"], cols["theta"]])
    if len(poses) == 0:
        raise FreeSpaceError(
            f"{where}: {inputs.candidates_csv} holds zero candidates; raise score.n_candidates"
        )
    if person:
        return _person_goals(cfg, inputs, outputs, cols, where)
    fs = FreeSpace.load(inputs.freespace_npz)
    valid = (cols["hit_fraction"] >= cfg.min_hit_fraction) & fs.contains(poses[:, :2])
    any_valid = valid.copy()
    registrable = (cols["seen_fraction"] >= cfg.min_seen_fraction) & (
        cols["matchable_points"] >= cfg.min_matchable_points
    )
    if cfg.method == "score" and (valid & registrable).any():
        valid &= registrable
    elif cfg.method == "score" and valid.any():
        log.warning(
            "%s: no candidate shows goals.min_seen_fraction = %.2f of photographed surface "
            "and goals.min_matchable_points = %d map points; goals ignore the overlap this "
            "round", where, cfg.min_seen_fraction, cfg.min_matchable_points,
        )  # fmt: skip
    abandoned = abandoned_goals(inputs.capture_logs)
    if cfg.method == "frontier":
        score = np.where(valid, cols["score_deg"], np.nan)
        return _frontier_goals(cfg, inputs, outputs, fs, score, where, abandoned)
    avoided = _avoid_abandoned(valid, poses, abandoned, cfg.nms_radius_m, where)
    front = None
    if cfg.open_frontiers:
        front = _open_frontiers(cfg, fs, inputs.previous_goals_json, abandoned)
        for g in front["goals"]:  # the score's goals differ from them as from each other
            pose = np.array([g["x"], g["y"], g["theta"]])
            valid &= ~same_view(poses, pose, cfg.nms_radius_m, cfg.nms_angle_deg)
    score = np.where(valid, cols["score_deg"], np.nan)
    ranked = select_goals(
        poses, score, cfg.k + cfg.backups, cfg.nms_radius_m, cfg.nms_angle_deg, valid
    )
    scored = any_valid & np.isfinite(cols["score_deg"])
    mean_score = float(np.mean(cols["score_deg"][scored])) if scored.any() else None
    map_images = _registered_images(inputs.sfm_dir)
    map_photos = _map_photos(inputs.sfm_dir)
    new_area = None
    prev_fs = inputs.previous_freespace_npz
    if prev_fs is not None and Path(prev_fs).is_file():
        new_area = fs.new_area_m2(FreeSpace.load(prev_fs), cfg.new_area_margin_m)
    returns = diminishing_returns(mean_score, fs.area_m2, inputs.previous_goals_json,
                                  cfg.min_score_gain, cfg.min_area_gain, map_images,
                                  new_area, patience=cfg.patience,
                                  map_photos=map_photos)  # fmt: skip
    n_front = 0 if front is None else len(front["goals"])
    chosen, backups = ranked[: cfg.k - n_front], ranked[cfg.k - n_front :]
    doc = goals_document(
        poses,
        score,
        chosen,
        cfg.complete_threshold_deg,
        where,
        extra={
            "n_valid": int(valid.sum()),
            "min_seen_fraction": cfg.min_seen_fraction,
            "min_matchable_points": cfg.min_matchable_points,
            # the best score over every candidate, registrable or not (for information:
            # "complete" and the goals only consider views a photo could be registered from)
            "best_score_any_deg": _best(np.where(any_valid, cols["score_deg"], np.nan)),
            "nms_radius_m": cfg.nms_radius_m,
            "nms_angle_deg": cfg.nms_angle_deg,
            "mean_score_deg": None if mean_score is None else round(mean_score, 4),
            "free_area_m2": round(fs.area_m2, 4),
            "map_images": map_images,
            "map_photos": map_photos,
            "score_gain": returns,
            "avoided": avoided,
        },
    )
    apply_stopping_rule(doc, returns, cfg.complete_threshold_deg)
    if front is not None:
        _apply_open_frontiers(doc, front, where)
    _apply_stuck(doc, idle_rounds(map_images, inputs.previous_goals_json, abandoned,
                                  cfg.patience, map_photos))  # fmt: skip
    if doc["complete"]:
        log.info("%s: exploration complete: %s", where, doc["complete_because"])
    # next in rank, for the planner to use in place of a goal it cannot route to
    spare = goals_document(poses, score, backups, 0.0, where)["goals"]
    doc["backups"] = [{**g, "rank": g["rank"] + len(chosen)} for g in spare]
    write_goals(outputs.goals_json, doc)
    if outputs.goals_png is not None:
        from scenebot.goals.plots import plot_goals

        title = f"{where}: goals (complete={doc['complete']})"
        plot_goals(outputs.goals_png, fs, poses, score, chosen, title, abandoned,
                   front)  # fmt: skip
    return doc


def _open_frontiers(cfg: GoalsConfig, fs: FreeSpace, previous_goals_json: Path | None,
                    abandoned: list[dict]) -> dict:  # fmt: skip
    """The round's open-frontier goals (:func:`scenebot.goals.frontier.open_frontier_goals`),
    away from the places visited for one in earlier rounds (the previous goals.json's
    ``frontiers_visited`` and its frontier goals) and from the goals abandoned so far."""
    from scenebot.goals.frontier import open_frontier_goals

    visited: list[dict] = []
    if previous_goals_json is not None and Path(previous_goals_json).is_file():
        prev = json.loads(Path(previous_goals_json).read_text(encoding="utf-8"))
        visited += list(prev.get("frontiers_visited") or [])
        visited += [{"x": g["x"], "y": g["y"]} for g in prev.get("goals", []) if g.get("frontier")]
    avoid = visited + [{"x": a["x"], "y": a["y"]} for a in abandoned]
    xy = np.array([[v["x"], v["y"]] for v in avoid], float).reshape(-1, 2)
    goals, boundary, unknown = open_frontier_goals(
        fs, fs.robot_radius, cfg.frontier_look_m, xy, cfg.k
    )
    return {"goals": goals, "boundary": boundary, "unknown": unknown, "visited": visited}


def _apply_open_frontiers(doc: dict, front: dict, where: str) -> None:
    """The open-frontier goals first in goals.json (``frontier: true``, then the score's,
    ranks after them); ``open_frontiers`` says what was found, ``frontiers_visited`` carries
    the places visited for one to the next round; a map with a frontier left is not
    complete (``complete_because`` then goes to ``not_complete_because``)."""
    goals = front["goals"]
    n = len(goals)
    doc["goals"] = [
        {**_goal_record(r, g), "frontier": True, "opening_m": g["opening_m"]}
        for r, g in enumerate(goals)
    ] + [{**g, "rank": g["rank"] + n} for g in doc["goals"]]
    doc["open_frontiers"] = {
        "goals": n,
        "boundary_cells": int(front["boundary"].sum()),
        "unknown_cells": int(front["unknown"].sum()),
        "visited": len(front["visited"]),
    }
    doc["frontiers_visited"] = front["visited"]
    if n and doc["complete"]:
        doc["complete"] = False
        doc["not_complete_because"] = (
            f"{n} open frontier(s) left (free space that ends where no wall does, widest "
            f"{goals[0]['opening_m']:.2f} m), though {doc.pop('complete_because')}"
        )
        log.info("%s: %s", where, doc["not_complete_because"])


def _avoid_abandoned(valid: np.ndarray, poses: np.ndarray, abandoned: list[dict],
                     radius_m: float, where: str) -> dict:  # fmt: skip
    """Take the candidates near goals abandoned in earlier rounds out of ``valid`` (in place;
    not when that leaves none, logged). Returns goals.json's ``avoided``."""
    near = near_abandoned(poses[:, :2], abandoned, radius_m) & valid
    applied = bool(near.any() and (valid & ~near).any())
    if applied:
        valid &= ~near
    elif near.any():
        log.warning(
            "%s: every valid candidate lies within goals.nms_radius_m = %g m of a goal "
            "abandoned in an earlier round; choosing among them anyway", where, radius_m,
        )  # fmt: skip
    return {"abandoned_goals": len(abandoned), "candidates": int(near.sum()),
            "applied": applied, "radius_m": radius_m}  # fmt: skip


def _apply_stuck(doc: dict, idle: dict | None) -> None:
    """goals.json's ``idle``; a stuck campaign stops (``complete`` with the reason)."""
    doc["idle"] = idle
    if idle and idle["stuck"] and not doc["complete"]:
        doc["complete"] = True
        doc["stuck"] = True
        doc["complete_because"] = idle["reason"]


def _registered_images(sfm_dir: Path | None) -> int | None:
    """Registered images of the round's map, None without one."""
    if sfm_dir is None or not (Path(sfm_dir) / "images.bin").is_file():
        return None
    import pycolmap

    return int(pycolmap.Reconstruction(str(sfm_dir)).num_reg_images())


def _map_photos(sfm_dir: Path | None) -> int | None:
    """The photos the round's sfm stage saw, every round's so far (its ``report.json``
    ``photos``, registered or not), None without it: with the previous round's, the round's
    new photos (an idle round: :func:`scenebot.goals.failures.is_idle`)."""
    report = None if sfm_dir is None else Path(sfm_dir) / "report.json"
    if report is None or not report.is_file():
        return None
    photos = json.loads(report.read_text(encoding="utf-8")).get("photos")
    return int(photos) if isinstance(photos, int) else None


def _best(score: np.ndarray) -> float | None:
    finite = np.isfinite(score)
    return round(float(np.max(score[finite])), 4) if finite.any() else None


def _goal_record(rank: int, g: dict) -> dict:
    x, y, t = round(g["x"], 4), round(g["y"], 4), round(g["theta"], 5)
    return {"rank": rank, "candidate": None, "x": x, "y": y, "theta": t, "score_deg": None}


def _frontier_goals(cfg: GoalsConfig, inputs: GoalsInputs, outputs: GoalsOutputs, fs: FreeSpace,
                    score: np.ndarray, where: str, abandoned: list[dict]) -> dict:  # fmt: skip
    """The frontier baseline (``goals.method: frontier``): see :mod:`scenebot.goals.frontier`.

    The candidates' scores are still reported (``best_score_deg``) so campaigns compare, but
    they choose nothing; the map is complete when no frontier is left, or the campaign is
    stuck (:func:`scenebot.goals.failures.idle_rounds`, as for the score's goals).
    """
    from scenebot.geometry import read_map_geometry
    from scenebot.goals.frontier import frontier_cells, frontier_goals, seen_cells

    if inputs.sfm_dir is None:
        raise ValueError(f"{where}: goals.method=frontier needs the map (round_XXX/sfm)")
    _, centres, _, headings = read_map_geometry(inputs.sfm_dir, with_headings=True)
    smap = read_sparse_map(inputs.sfm_dir)
    intr = smap.intrinsics[0]
    hfov = float(np.degrees(2 * np.arctan(0.5 * intr.width / intr.fx)))
    seen = seen_cells(fs, centres[:, :2], headings, hfov, cfg.frontier_range_m)
    area = cfg.frontier_min_area_m2
    goals = frontier_goals(
        fs, seen, centres[-1, :2], cfg.k, cfg.nms_radius_m, cfg.frontier_look_m, area
    )
    finite = np.isfinite(score)
    doc = {
        "round": where,
        "method": "frontier",
        "complete": not goals,
        "best_score_deg": round(float(np.max(score[finite])), 4) if finite.any() else None,
        "threshold_deg": cfg.complete_threshold_deg,
        "n_candidates": len(score),
        "pose_convention": "camera centre x, y (m, map frame) and heading theta (rad, ccw from x)",
        "seen_free_fraction": float(seen.sum() / max(fs.mask.sum(), 1)),
        "map_images": len(centres),
        "map_photos": _map_photos(inputs.sfm_dir),
        "goals": [_goal_record(r, g) for r, g in enumerate(goals)],
    }
    if doc["complete"]:
        doc["complete_because"] = "no frontier left"
    _apply_stuck(doc, idle_rounds(len(centres), inputs.previous_goals_json, abandoned,
                                  cfg.patience, doc["map_photos"]))  # fmt: skip
    write_goals(outputs.goals_json, doc)
    if outputs.goals_png is not None:
        from scenebot.goals.plots import plot_frontier

        plot_frontier(
            outputs.goals_png, fs, seen, frontier_cells(fs, seen, area), centres[:, :2], goals,
            f"{where}: frontier goals (complete={doc['complete']}, "
            f"{100 * doc['seen_free_fraction']:.0f}% of the free space seen)",
        )  # fmt: skip
    return doc


COVERAGE_VERTICES = 20000
"""Mesh vertices (a seeded sample) whose photo counts the coverage picture shows."""


def _close_ups(
    cfg: GoalsConfig, poses: np.ndarray, which: np.ndarray, mesh_ply: Path | None, smap
) -> np.ndarray:
    """(N,) bool: which of the candidates ``which`` see the round's mesh from nearer than
    ``goals.person_min_depth_m`` (median depth, :func:`~scenebot.goals.depth.view_depths`;
    the field of view of ``smap``'s median photo); none without a mesh or a map, or with
    the bound 0."""
    out = np.zeros(len(poses), bool)
    if cfg.person_min_depth_m <= 0 or mesh_ply is None or smap is None or not smap.intrinsics:
        return out
    if not which.any():
        return out
    from scenebot.artifacts.mesh import read_mesh
    from scenebot.goals.depth import view_depths

    intr = smap.intrinsics[len(smap.intrinsics) // 2]
    hfov = float(np.degrees(2 * np.arctan(0.5 * intr.width / intr.fx)))
    aspect = (intr.height / intr.fy) / (intr.width / intr.fx)
    V, F = read_mesh(mesh_ply)
    idx = np.flatnonzero(which)
    out[idx] = view_depths(poses[idx], hfov, aspect, V, F) < cfg.person_min_depth_m
    log.info(
        "%d of %d registrable candidates see their surface from nearer than "
        "goals.person_min_depth_m = %g m (a close-up does not register): not asked for",
        int(out.sum()), len(idx), cfg.person_min_depth_m,
    )  # fmt: skip
    return out


def _person_min_matchable(cfg: GoalsConfig, sfm_dir: Path | None) -> int:
    """The map points a person's shot must be predicted to match: ``goals.min_matchable_points``,
    or ``goals.person_min_matchable_share`` of what the map's median photo observes when
    more; ``min_matchable_points`` 0 turns both off."""
    if sfm_dir is None or cfg.person_min_matchable_share <= 0 or cfg.min_matchable_points <= 0:
        return cfg.min_matchable_points
    import pycolmap

    rec = pycolmap.Reconstruction(str(sfm_dir))
    seen = [rec.image(i).num_points3D for i in rec.reg_image_ids()]
    median = float(np.median(seen)) if seen else 0.0
    return max(cfg.min_matchable_points, round(cfg.person_min_matchable_share * median))


def _person_goals(cfg: GoalsConfig, inputs: GoalsInputs, outputs: GoalsOutputs, cols: dict,
                  where: str) -> dict:  # fmt: skip
    """The next shots of a person (``robot: photos``): the score method's choice among the
    six-degree-of-freedom candidates in the 3-D free space, spaced in 3-D
    (:func:`~scenebot.goals.select.select_goals_3d`: ``goals.nms_radius_m`` apart, or
    ``goals.nms_angle_deg`` apart in viewing direction).

    The map is complete only when the free space is not degenerate (enough voxels, a camera
    in it: :meth:`~scenebot.artifacts.freespace.FreeVolume.degenerate`), some candidate in it
    could be registered, and the best such view scores below ``goals.complete_threshold_deg``.
    In a guided campaign (``robot: guided``, ``person-sim``: a previous round's goals.json)
    the stopping rule is the robot's: diminishing returns of the mean view score and the free
    volume (``goals.min_score_gain``, ``min_area_gain`` of the volume, ``patience``), and a
    campaign whose rounds are idle (most new photos not in the map) stops as stuck. A folder of
    photos is one round, so neither applies there.
    """
    from scenebot.artifacts.freespace import FreeVolume
    from scenebot.goals.select import select_goals_3d

    if cfg.method != "score":
        raise ValueError(
            f"{where}: goals.method = {cfg.method} works on a robot's plane; a person's photos "
            "(robot: photos) take goals.method: score"
        )
    vol = FreeVolume.load(inputs.freespace_npz)
    poses = np.column_stack([cols[c] for c in ("x", "y", "z", "theta", "pitch")])
    inside = vol.contains(poses[:, :3])
    valid = (cols["hit_fraction"] >= cfg.min_hit_fraction) & inside
    any_valid = valid.copy()
    min_points = _person_min_matchable(cfg, inputs.sfm_dir)
    registrable = (cols["seen_fraction"] >= cfg.min_seen_fraction) & (
        cols["matchable_points"] >= min_points
    )
    smap = read_sparse_map(inputs.sfm_dir) if inputs.sfm_dir is not None else None
    close = _close_ups(cfg, poses, valid & registrable, inputs.mesh_ply, smap)
    registrable &= ~close
    if (valid & registrable).any():
        valid &= registrable
    elif valid.any():
        log.warning("%s: no candidate could be registered (goals.min_seen_fraction, "
                    "goals.min_matchable_points, goals.person_min_matchable_share: %d "
                    "points, goals.person_min_depth_m); goals ignore the overlap",
                    where, min_points)  # fmt: skip
    abandoned = unfulfilled_shots(inputs.fulfilment_json)
    avoided = _avoid_abandoned(valid, poses, abandoned, cfg.nms_radius_m, where)
    score = np.where(valid, cols["score_deg"], np.nan)
    ranked = select_goals_3d(
        poses, score, cfg.k + cfg.backups, cfg.nms_radius_m, cfg.nms_angle_deg, valid
    )
    chosen, backups = ranked[: cfg.k], ranked[cfg.k :]
    scored = any_valid & np.isfinite(cols["score_deg"])
    coverage = _coverage(inputs.mesh_ply, smap)
    doc = goals_document(
        poses, score, chosen, cfg.complete_threshold_deg, where,
        extra={
            "mode": "person (robot: photos): six degrees of freedom",
            "n_valid": int(valid.sum()),
            "n_in_free_space": int(inside.sum()),
            "min_seen_fraction": cfg.min_seen_fraction,
            "min_matchable_points": min_points,
            "min_depth_m": cfg.person_min_depth_m,
            "close_ups": int(close.sum()),
            "best_score_any_deg": _best(np.where(any_valid, cols["score_deg"], np.nan)),
            "nms_radius_m": cfg.nms_radius_m,
            "nms_angle_deg": cfg.nms_angle_deg,
            "mean_score_deg": round(float(np.mean(cols["score_deg"][scored])), 4)
            if scored.any() else None,
            "free_volume_m3": round(vol.volume_m3, 6),
            "free_voxels": vol.n_free,
            "camera_height": round(vol.camera_height, 4),
            "map_images": None if smap is None else len(smap.names),
            "map_photos": _map_photos(inputs.sfm_dir),
            "coverage": None if coverage is None else coverage[2],
            "avoided": avoided,
        },
    )  # fmt: skip
    returns = diminishing_returns(
        doc["mean_score_deg"], vol.volume_m3, inputs.previous_goals_json, cfg.min_score_gain,
        cfg.min_area_gain, doc["map_images"], patience=cfg.patience, size_key="free_volume_m3",
        map_photos=doc["map_photos"],
    )  # fmt: skip
    doc["score_gain"] = returns
    apply_stopping_rule(doc, returns, cfg.complete_threshold_deg)
    _apply_stuck(doc, idle_rounds(doc["map_images"], inputs.previous_goals_json, abandoned,
                                  cfg.patience, doc["map_photos"]))  # fmt: skip
    degenerate = vol.degenerate()
    if degenerate is not None or not valid.any():
        doc["complete"] = False
        doc.pop("complete_because", None)
        doc["not_complete_because"] = (
            f"the free space is degenerate: {degenerate}" if degenerate is not None else
            f"no candidate in the free space hits goals.min_hit_fraction = "
            f"{cfg.min_hit_fraction} of its view on the map"
        )  # fmt: skip
    spare = goals_document(poses, score, backups, 0.0, where)["goals"]
    doc["backups"] = [{**g, "rank": g["rank"] + len(chosen)} for g in spare]
    write_goals(outputs.goals_json, doc)
    if outputs.goals_png is not None and smap is not None:
        from scenebot.geometry import read_map_geometry
        from scenebot.goals.plots import plot_person_goals

        fwd = smap.R[:, 2]  # each photo's optical axis
        taken = np.column_stack([smap.centres, np.arctan2(fwd[:, 1], fwd[:, 0]),
                                 np.arcsin(np.clip(fwd[:, 2], -1, 1))])  # fmt: skip
        surface, seen_by = (coverage[0], coverage[1]) if coverage is not None else (
            read_map_geometry(inputs.sfm_dir)[0], None)  # fmt: skip
        if seen_by is None:
            seen_by = np.full(len(surface), 2)
        plot_person_goals(
            outputs.goals_png, vol, taken, smap.intrinsics[0], poses[chosen],
            cols["score_deg"][chosen], surface, seen_by,
            np.array([[a["x"], a["y"]] for a in abandoned]).reshape(-1, 2),
            f"{where}: the next {len(chosen)} shots (complete={doc['complete']}); predicted "
            "gain = view score (deg, the rendering error a photo there removes)",
        )  # fmt: skip
    return doc


def _coverage(mesh_ply: Path | None, smap) -> tuple[np.ndarray, np.ndarray, dict] | None:
    """Photos seeing the map's surface (a sample of mesh vertices) and its summary; None
    without the mesh or the map."""
    if mesh_ply is None or smap is None or not Path(mesh_ply).is_file():
        return None
    from scenebot.artifacts.mesh import read_mesh
    from scenebot.goals.coverage import photo_counts

    V, F = read_mesh(mesh_ply)
    pts, seen_by = photo_counts(V, F, smap, COVERAGE_VERTICES, np.random.default_rng(0))
    summary = {
        "vertices_sampled": len(pts),
        "seen_by_fewer_than_2": round(float(np.mean(seen_by < 2)), 4) if len(pts) else None,
        "seen_by_none": round(float(np.mean(seen_by == 0)), 4) if len(pts) else None,
        "median_photos": float(np.median(seen_by)) if len(pts) else None,
    }
    return pts, seen_by, summary
