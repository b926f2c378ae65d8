"""Entry points of the ``mesh``, ``score`` and ``goals`` stages.

Each is a plain function ``run_<stage>(cfg, inputs, outputs)`` with typed dataclass inputs and
outputs, so Snakemake rules and the CLI call the same code. The round's name (e.g.
``round_002``) is taken from the paths for error messages.
"""

from __future__ import annotations

import json
import logging
import re
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scenebot.score.candidates import read_candidates, sample_candidates, write_candidates
from scenebot.score.config import GoalsConfig, MeshConfig, ScoreConfig
from scenebot.score.freespace import (
    FreeSpace,
    FreeSpaceError,
    compute_freespace,
    observation_rays,
)
from scenebot.score.geometry import candidate_views, read_sparse_map
from scenebot.score.goals import goals_document, select_goals, write_goals
from scenebot.score.matchable import matchable_points
from scenebot.score.mesh import MeshError, build_mesh, check_mesh, decimate, read_mesh, write_mesh

log = logging.getLogger(__name__)


def round_name(*paths: str | Path) -> str:
    """``round_XXX`` found in the paths, else the first path (for messages)."""
    for p in paths:
        m = re.search(r"round_\d+", str(p))
        if m:
            return m.group(0)
    return str(paths[0]) if paths else "?"


@dataclass
class MeshInputs:
    """Inputs of the mesh stage: ``sfm_dir`` = ``round_{r}/sfm/`` (COLMAP binary model)."""

    sfm_dir: Path


@dataclass
class MeshOutputs:
    """Outputs: ``mesh.ply``, ``freespace.json``, ``freespace.npz``, ``freespace.png``."""

    mesh_ply: Path
    freespace_json: Path
    freespace_npz: Path
    freespace_png: Path | None = None


def run_mesh(cfg: MeshConfig, inputs: MeshInputs, outputs: MeshOutputs) -> dict:
    """Poisson mesh of the map and its free space.

    Returns:
        Summary: vertex/face counts, free area (m^2), whether the free space is closed.
    """
    where = round_name(inputs.sfm_dir, outputs.mesh_ply)
    smap = read_sparse_map(inputs.sfm_dir)
    if len(smap.names) == 0:
        raise MeshError(f"{where}: the map in {inputs.sfm_dir} has no registered images")
    V, F = build_mesh(smap.xyz, smap.view_dir, smap.track_len, cfg, where, smap.centres)
    write_mesh(outputs.mesh_ply, V, F)
    cam_xy = smap.centres[:, :2]
    rays = observation_rays(inputs.sfm_dir, cfg.min_track_length) if cfg.seen_free_space else None
    fs = compute_freespace(
        V, F, cam_xy, cfg.robot_radius_m, cfg.cut_heights_m, cfg.grid_resolution_m, where,
        rays=rays,
    )  # fmt: skip
    fs.save(outputs.freespace_json, outputs.freespace_npz, where)
    if outputs.freespace_png is not None:
        from scenebot.score.plots import plot_freespace

        plot_freespace(outputs.freespace_png, fs, cam_xy, where)
    return {
        "vertices": len(V),
        "faces": len(F),
        "free_area_m2": fs.area_m2,
        "closed": fs.closed,
    }


@dataclass
class ScoreInputs:
    """Inputs of the score stage (all from the same round)."""

    sfm_dir: Path
    mesh_ply: Path
    freespace_npz: Path


@dataclass
class ScoreOutputs:
    """Outputs: ``candidates.csv`` and an optional picture of the top candidates' pixels."""

    candidates_csv: Path
    views_png: Path | None = None


def make_scorer(cfg: ScoreConfig, V: np.ndarray, F: np.ndarray, smap, where: str):
    """A :class:`~scenebot.score.kernel.TaichiScorer` for a map and its (decimated) mesh."""
    from scenebot.score.kernel import TaichiScorer, source_views_for_depth

    if len(smap.names) == 0:
        raise MeshError(f"{where}: the map has no registered images to score against")
    Vd, Fd = decimate(V, F, cfg.max_triangles)
    check_mesh(Vd, Fd, f"{where} (decimated to score.max_triangles = {cfg.max_triangles})")
    src, size = source_views_for_depth(smap.R, smap.t, smap.intrinsics, cfg.source_depth_width)
    intr = smap.intrinsics[0].scaled(cfg.width, cfg.height)
    return TaichiScorer(
        Vd,
        Fd,
        src,
        size,
        intr,
        depth_tolerance=cfg.depth_tolerance,
        near_m=cfg.near_m,
        batch_size=cfg.batch_size,
        backend=cfg.backend,
    )


def run_score(cfg: ScoreConfig, inputs: ScoreInputs, outputs: ScoreOutputs) -> dict:
    """Sample candidates in free space and score them.

    Returns:
        Summary: candidate count, evaluation rate (candidates/s), taichi arch, triangles.
    """
    where = round_name(inputs.mesh_ply, outputs.candidates_csv)
    smap = read_sparse_map(inputs.sfm_dir)
    V, F = read_mesh(inputs.mesh_ply)
    check_mesh(V, F, f"{where} {inputs.mesh_ply}")
    fs = FreeSpace.load(inputs.freespace_npz)
    poses = sample_candidates(fs, cfg.n_candidates, np.random.default_rng(cfg.seed), where)
    scorer = make_scorer(cfg, V, F, smap, where)
    views = candidate_views(poses, scorer.intr)
    t0 = time.perf_counter()
    res = scorer.score_views(views)
    dt = time.perf_counter() - t0
    matchable = matchable_points(
        views,
        scorer.intr.width,
        scorer.intr.height,
        smap.xyz,
        smap.view_dir,
        smap.view_dist,
        cfg.match_angle_deg,
        cfg.match_scale_ratio,
        cfg.near_m,
    )
    write_candidates(
        outputs.candidates_csv,
        poses,
        {
            "score_deg": res.score_deg,
            "hit_fraction": res.hit_fraction,
            "seen_fraction": res.seen_fraction,
            "matchable_points": matchable,
        },
    )
    if outputs.views_png is not None and cfg.plot_top > 0:
        from scenebot.score.kernel import summarize
        from scenebot.score.plots import plot_top_views

        s = np.where(np.isfinite(res.score_deg), res.score_deg, -np.inf)
        top = np.argsort(-s)[: min(cfg.plot_top, scorer.batch)]
        top_res = scorer.score_views(views[top], return_pixels=True)
        depth = scorer.render_depth(views[top])
        plot_top_views(
            outputs.views_png,
            depth,
            top_res.pixels,
            summarize(top_res.pixels)[0],
            f"{where}: highest-scoring candidates",
        )
    summary = {
        "candidates": len(poses),
        "seconds": dt,
        "evals_per_s": len(poses) / dt if dt > 0 else float("inf"),
        "arch": scorer.arch,
        "triangles": int(scorer._faces.shape[0]),
        "sources": scorer.n_src,
    }
    log.info("%s: scored %s", where, summary)
    return summary


@dataclass
class GoalsInputs:
    """Inputs of the goals stage."""

    candidates_csv: Path
    freespace_npz: Path
    sfm_dir: Path | None = None  # the map (camera poses); the frontier method needs it
    previous_goals_json: Path | None = None  # the previous round's (diminishing returns)
    previous_freespace_npz: Path | None = None  # the previous round's (its new free space)


@dataclass
class GoalsOutputs:
    """Outputs: ``goals.json`` and an optional heat-map picture."""

    goals_json: Path
    goals_png: Path | None = None


def run_goals(cfg: GoalsConfig, inputs: GoalsInputs, outputs: GoalsOutputs) -> dict:
    """Choose the goals of the next round and decide whether exploration is complete.

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
    score = np.where(valid, cols["score_deg"], np.nan)
    if cfg.method == "frontier":
        return _frontier_goals(cfg, inputs, outputs, fs, score, where)
    ranked = select_goals(
        poses, score, cfg.k + cfg.backups, cfg.nms_radius_m, cfg.nms_angle_deg, valid
    )
    scored = any_valid & np.isfinite(cols["score_deg"])
    mean_score = float(np.mean(cols["score_deg"][scored])) if scored.any() else None
    map_images = _registered_images(inputs.sfm_dir)
    new_area = None
    prev_fs = inputs.previous_freespace_npz
    if prev_fs is not None and Path(prev_fs).is_file():
        new_area = fs.new_area_m2(FreeSpace.load(prev_fs), cfg.new_area_margin_m)
    returns = diminishing_returns(mean_score, fs.area_m2, inputs.previous_goals_json,
                                  cfg.min_score_gain, cfg.min_area_gain, map_images,
                                  new_area, cfg.patience)  # fmt: skip
    chosen, backups = ranked[: cfg.k], ranked[cfg.k :]
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
            "score_gain": returns,
        },
    )
    if returns is not None and returns["complete"] and not doc["complete"]:
        doc["complete"] = True
        doc["complete_because"] = returns["reason"]
    elif doc["complete"]:
        doc["complete_because"] = (
            f"best view score {doc['best_score_deg']} deg < goals.complete_threshold_deg "
            f"= {cfg.complete_threshold_deg}"
        )
    if doc["complete"]:
        log.info("%s: exploration complete: %s", where, doc["complete_because"])
    # next in rank, for the planner to use in place of a goal it cannot route to
    spare = goals_document(poses, score, backups, 0.0, where)["goals"]
    doc["backups"] = [{**g, "rank": g["rank"] + len(chosen)} for g in spare]
    write_goals(outputs.goals_json, doc)
    if outputs.goals_png is not None:
        from scenebot.score.plots import plot_goals

        title = f"{where}: goals (complete={doc['complete']})"
        plot_goals(outputs.goals_png, fs, poses, score, chosen, title)
    return doc


def diminishing_returns(
    mean_score: float | None,
    free_area_m2: float,
    previous_goals_json: Path | None,
    min_gain: float,
    min_area_gain: float,
    map_images: int | None = None,
    new_area_m2: float | None = None,
    patience: int = 1,
) -> dict | None:
    """What the last round bought, and whether that is too little to go on.

    Two measures, each against the previous round's ``goals.json``: the mean view score over
    the candidates (the predicted rendering error averaged over the free space) and the free
    space. Photos of known space lower the mean; photos that open space the map did not know
    (another room behind a doorway) add free space, and raise the mean while the new space is
    still unphotographed. The map is complete when the mean moved by less than ``min_gain``
    (a fraction of the previous mean) either way *and* the new free space (``new_area_m2``:
    this round's free space away from the previous round's; without it, the net growth of
    the free area) is less than ``min_area_gain`` of the previous free area. The net growth
    alone misses a corridor that opens while the map's walls close in elsewhere. None for
    round 0 (no previous ``goals.json``) or when a measure is missing.

    One round's gain is noisy, so the map is complete only when the gain was that low in
    ``patience`` consecutive rounds (``low_rounds`` counts them; the previous round's count
    comes from its ``goals.json``).

    A round that added no photo to the map (``map_images``, the registered images, no more
    than the previous round's: its goals were not reached) measured nothing, so it cannot
    show diminishing returns: the test is not applied, and the next round tries again.
    """
    if mean_score is None or previous_goals_json is None or not previous_goals_json.is_file():
        return None
    prev_doc = json.loads(previous_goals_json.read_text(encoding="utf-8"))
    prev, prev_area = prev_doc.get("mean_score_deg"), prev_doc.get("free_area_m2")
    if not prev or not prev_area:
        return None
    gain = (prev - mean_score) / prev
    area_gain = (free_area_m2 - prev_area) / prev_area
    new_gain = None if new_area_m2 is None else new_area_m2 / prev_area
    grew = area_gain if new_gain is None else new_gain
    out = {"previous_mean_score_deg": prev, "mean_score_deg": round(mean_score, 4),
           "gain": round(gain, 4), "min_gain": min_gain,
           "previous_free_area_m2": prev_area, "free_area_m2": round(free_area_m2, 4),
           "area_gain": round(area_gain, 4), "min_area_gain": min_area_gain,
           "new_area_m2": None if new_area_m2 is None else round(new_area_m2, 4),
           "new_area_gain": None if new_gain is None else round(new_gain, 4)}  # fmt: skip
    prev_low = int((prev_doc.get("score_gain") or {}).get("low_rounds", 0))
    prev_images = prev_doc.get("map_images")
    no_photo = map_images is not None and prev_images is not None and map_images <= prev_images
    if map_images is not None and prev_images is not None:
        out["map_images"], out["previous_map_images"] = map_images, prev_images
    if no_photo:
        out["not_applied"] = (
            f"the last round added no photo to the map ({prev_images} -> {map_images} "
            "registered images: its goals were not reached), so no change in the score "
            "says nothing about what more photos would bring"
        )
    out["low"] = bool(not no_photo and min_gain > 0 and abs(gain) < min_gain
                      and grew < min_area_gain)  # fmt: skip
    out["low_rounds"] = prev_low + 1 if out["low"] else (prev_low if no_photo else 0)
    out["patience"] = patience
    out["complete"] = not no_photo and out["low_rounds"] >= max(patience, 1)
    if out["complete"]:
        out["reason"] = (
            f"diminishing returns: since the previous round the mean view score changed by "
            f"{-100 * gain:+.1f}% ({prev:.1f} -> {mean_score:.1f} deg; goals.min_score_gain "
            f"= {100 * min_gain:.0f}%) and the free space by {100 * area_gain:+.1f}% "
            f"({prev_area:.1f} -> {free_area_m2:.1f} m^2"
            + ("" if new_area_m2 is None else f", {new_area_m2:.2f} m^2 of it new")
            + f"; goals.min_area_gain = {100 * min_area_gain:.0f}%)"
            + ("" if patience <= 1 else f", {out['low_rounds']} rounds in a row "
               f"(goals.patience = {patience})")
        )  # fmt: skip
    return out


def _registered_images(sfm_dir: Path | None) -> int | None:
    """Registered images of the round's map, None without one."""
    if sfm_dir is None or not (Path(sfm_dir) / "images.bin").is_file():
        return None
    import pycolmap

    return int(pycolmap.Reconstruction(str(sfm_dir)).num_reg_images())


def _best(score: np.ndarray) -> float | None:
    finite = np.isfinite(score)
    return round(float(np.max(score[finite])), 4) if finite.any() else None


def _goal_record(rank: int, g: dict) -> dict:
    x, y, t = round(g["x"], 4), round(g["y"], 4), round(g["theta"], 5)
    return {"rank": rank, "candidate": None, "x": x, "y": y, "theta": t, "score_deg": None}


def _frontier_goals(cfg: GoalsConfig, inputs: GoalsInputs, outputs: GoalsOutputs, fs: FreeSpace,
                    score: np.ndarray, where: str) -> dict:  # fmt: skip
    """The frontier baseline (``goals.method: frontier``): see :mod:`scenebot.score.frontier`.

    The candidates' scores are still reported (``best_score_deg``) so campaigns compare, but
    they choose nothing; the map is complete when no frontier is left.
    """
    from scenebot.geometry import read_map_geometry
    from scenebot.score.frontier import frontier_cells, frontier_goals, seen_cells

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
        "goals": [_goal_record(r, g) for r, g in enumerate(goals)],
    }
    write_goals(outputs.goals_json, doc)
    if outputs.goals_png is not None:
        from scenebot.score.plots import plot_frontier

        plot_frontier(
            outputs.goals_png, fs, seen, frontier_cells(fs, seen, area), centres[:, :2], goals,
            f"{where}: frontier goals (complete={doc['complete']}, "
            f"{100 * doc['seen_free_fraction']:.0f}% of the free space seen)",
        )  # fmt: skip
    return doc
