"""The score stage's entry point: ``run(cfg, inputs, outputs)`` with the rule's paths."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scenebot.artifacts import round_name
from scenebot.artifacts.candidates import write_candidates
from scenebot.artifacts.freespace import FreeSpace, FreeVolume
from scenebot.artifacts.mesh import MeshError, check_mesh, decimate, read_mesh
from scenebot.geometry import mount_pitch, read_sparse_map
from scenebot.score.candidates import sample_candidates, sample_person_candidates
from scenebot.score.config import ScoreConfig
from scenebot.score.geometry import candidate_views, person_views
from scenebot.score.matchable import matchable_points

log = logging.getLogger(__name__)


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


def run(cfg: ScoreConfig, inputs: ScoreInputs, outputs: ScoreOutputs, person: bool = False) -> dict:
    """Sample candidates in free space and score them.

    Args:
        cfg: score settings.
        inputs: the round's map, mesh and free space.
        outputs: the files to write.
        person: the photos are a person's (``robot: photos``): candidates in six degrees of
            freedom in the 3-D free space (``score.person``), not a robot's in the plane.

    Returns:
        Summary: candidate count, evaluation rate (candidates/s), taichi arch, triangles.
    """
    where = round_name(inputs.mesh_ply, outputs.candidates_csv)
    smap = read_sparse_map(inputs.sfm_dir)
    V, F = read_mesh(inputs.mesh_ply)
    check_mesh(V, F, f"{where} {inputs.mesh_ply}")
    rng = np.random.default_rng(cfg.seed)
    if person:
        scorer = make_scorer(cfg, V, F, smap, where)
        vol = FreeVolume.load(inputs.freespace_npz)
        Vd, Fd = decimate(V, F, cfg.max_triangles)
        poses = sample_person_candidates(
            vol, Vd, Fd, cfg.n_candidates, cfg.person, scorer.intr, rng, where
        )
        views = person_views(poses, scorer.intr)
    else:
        fs = FreeSpace.load(inputs.freespace_npz)
        planar = sample_candidates(fs, cfg.n_candidates, rng, where)
        scorer = make_scorer(cfg, V, F, smap, where)
        # the robot's camera as its mount holds it: the map's photos say how it tilts
        pitch = mount_pitch(smap.R)
        views = candidate_views(planar, scorer.intr, pitch)
        n = len(planar)
        poses = np.column_stack([planar[:, :2], np.zeros(n), planar[:, 2], np.full(n, pitch)])
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
