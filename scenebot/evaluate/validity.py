"""Score validity: does the paper's angle heuristic predict how well a view can be synthesized?

The paper's key claim (section IV.B) is that the score of a candidate viewpoint -- the mean
over its pixels of the smallest angle between the candidate's ray and a photo's ray to the
same surface point -- predicts how poorly an image synthesized there would turn out, so the
robot should go where it is high. This module tests the claim directly (simulated scenes):

1. Round ``r``'s scored candidates (``round_{r}/candidates.csv``: the very poses and scores
   the goals stage chose from) whose render hits the map's mesh on enough pixels to have a
   score are taken in a random (seeded) order until ``M`` of them have a true view (step 4).
2. Each candidate is synthesized by unstructured lumigraph rendering (:mod:`scenebot.tour`)
   from round ``r``'s photos at their round-``r`` poses. The geometric proxy is the campaign's
   dense cloud, brought into round ``r``'s frame by the similarity between the two maps'
   camera centres (the same photos): the best geometry there is, so what the render lacks is
   the photos, which is what the score measures.
3. The same pose is rendered by the simulator from the true scene (no sensor noise); the pose
   goes to the world frame through the similarity of round ``r``'s camera centres to their
   true centres (evaluation only: no decision reads it).
4. PSNR and SSIM of synthesized vs true; Spearman's rank correlation between the score and
   PSNR (the paper predicts it negative: a high angle, a poor render), with a bootstrap
   interval; a scatter plot. A candidate the map's free space put inside, against or outside
   the true scene (its true render hits it on under half the pixels, or its median depth is
   under 15 cm) is left out and listed. The
   dense proxy has holes (textureless walls get no depth): such views render black whatever
   their photos, so rho is also given over the candidates the proxy covers (>= 50%).

Entry point :func:`run_validity`; ``python -m scenebot validity`` and the ``validity`` rule
call it.
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scenebot.evaluate.metrics import EvaluationError, robot_to_world

LOG = logging.getLogger(__name__)

MIN_TRUE_HIT = 0.5
"""A candidate whose true render hits the scene on fewer pixels is left out (outside it)."""
MIN_TRUE_DEPTH_M = 0.15
"""...or whose true render's median depth is below this (m): the pose is against a surface."""
PSNR_CAP_DB = 99.0
"""PSNR of identical images (infinite) is written as this."""


@dataclass
class ValidityInputs:
    """Inputs of the score-validity study.

    Attributes:
        round_dir: ``results/{scene}/round_{r}`` (``sfm/``, ``candidates.csv``).
        image_dir: folder the model's image names are relative to (``results/{scene}``).
        captures: capture folders of rounds 0..r (the photos' true poses, for the world frame).
        dense_ply: the campaign's proxy (``final/tour/proxy.npz``, the proxy rule) or its
            fused cloud (``final/dense/fused.ply``) to build the proxy from.
        dense_sfm_dir: the map the dense cloud was made from (the last round's ``sfm/``).
    """

    round_dir: Path
    image_dir: Path
    captures: list[Path]
    dense_ply: Path
    dense_sfm_dir: Path


def spearman(a: np.ndarray, b: np.ndarray) -> float:
    """Spearman's rank correlation (average ranks for ties); NaN with fewer than 3 pairs."""
    from scipy.stats import spearmanr

    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    if len(a) < 3 or np.ptp(a) == 0 or np.ptp(b) == 0:
        return float("nan")
    return float(spearmanr(a, b).statistic)


def bootstrap_interval(a, b, n: int = 1000, *, seed: int) -> tuple[float, float]:
    """95% percentile-bootstrap interval of :func:`spearman` over the pairs."""
    from scipy.stats import rankdata

    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    if len(a) < 3:
        return float("nan"), float("nan")
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, len(a), size=(n, len(a)))
    ra = np.apply_along_axis(rankdata, 1, a[idx])
    rb = np.apply_along_axis(rankdata, 1, b[idx])
    ra -= ra.mean(1, keepdims=True)
    rb -= rb.mean(1, keepdims=True)
    den = np.sqrt((ra * ra).sum(1) * (rb * rb).sum(1))
    rho = np.where(den > 0, (ra * rb).sum(1) / np.where(den > 0, den, 1), np.nan)
    lo, hi = np.nanpercentile(rho, [2.5, 97.5])
    return float(lo), float(hi)


def model_similarity(src_dir: Path, dst_dir: Path) -> tuple[float, np.ndarray, np.ndarray, int]:
    """Similarity ``x_dst = s R x_src + t`` between two maps from their shared photos' centres.

    Raises:
        EvaluationError: fewer than 3 photos registered in both.
    """
    import pycolmap

    from scenebot.sfm.evaluate import robust_similarity

    def centres(d: Path) -> dict[str, np.ndarray]:
        if not (Path(d) / "images.bin").is_file():
            raise EvaluationError(f"no COLMAP model in {d} (images.bin missing)")
        rec = pycolmap.Reconstruction(str(d))
        return {
            rec.image(i).name: np.asarray(rec.image(i).projection_center())
            for i in rec.reg_image_ids()
        }

    a, b = centres(src_dir), centres(dst_dir)
    common = sorted(set(a) & set(b))
    if len(common) < 3:
        raise EvaluationError(
            f"{src_dir} and {dst_dir} share {len(common)} registered photos (need 3): the dense "
            "cloud cannot be brought into the round's frame"
        )
    s, R, t, _, _ = robust_similarity(
        np.array([a[n] for n in common]), np.array([b[n] for n in common])
    )
    return float(s), R, t, len(common)


def _candidate_pose(
    x: float, y: float, theta: float, z: float = 0.0, pitch: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """cam_from_world (R, t) of a scored candidate: the score stage's horizontal camera at
    z = 0, or a person's camera (``z``, ``pitch``: six degrees of freedom)."""
    from scenebot.geometry import tilted_cam_from_world

    Rt = tilted_cam_from_world(np.array([[x, y, z]]), np.array([theta]), np.array([pitch]))[0]
    return Rt[:9].reshape(3, 3), Rt[9:]


def pick_candidates(cands: dict, m: int, min_hit: float, seed: int) -> np.ndarray:
    """Indices of ``m`` random scored candidates that hit the mesh on ``min_hit`` of pixels,
    in the (seeded) order they were drawn."""
    ok = np.isfinite(cands["score_deg"]) & (cands["hit_fraction"] >= min_hit)
    idx = np.flatnonzero(ok)
    if len(idx) < 3:
        raise EvaluationError(
            f"only {len(idx)} candidates have a score with hit fraction >= {min_hit}: too few "
            "for a correlation (raise score.n_candidates)"
        )
    rng = np.random.default_rng(seed)
    return rng.choice(idx, size=min(m, len(idx)), replace=False)


@dataclass
class _Synthesis:
    """Round ``r``'s ULR renderer on the campaign's dense cloud, and the camera it renders.

    Attributes:
        ulr: the :class:`~scenebot.tour.ulr.UlrRenderer`.
        cam: the novel views' pinhole :class:`~scenebot.tour.camera.Camera`.
        proxy: the dense cloud in round ``r``'s frame.
        sources: round ``r``'s photos.
        scale: scale of the similarity from the dense cloud's map to round ``r``'s.
        shared_photos: photos registered in both maps (that similarity's support).
    """

    ulr: object
    cam: object
    proxy: object
    sources: list
    scale: float
    shared_photos: int


def _synthesis(cfg, inputs: ValidityInputs, rdir: Path) -> _Synthesis:
    """The renderer: round r's photos, the dense cloud moved into round r's frame."""
    import pycolmap

    from scenebot.taichi_setup import init_taichi
    from scenebot.tour.camera import Camera
    from scenebot.tour.proxy import load_proxy
    from scenebot.tour.ulr import UlrRenderer, load_sources

    init_taichi(cfg.tour.taichi_arch, cfg.tour.num_threads)
    s, R, t, n_common = model_similarity(Path(inputs.dense_sfm_dir), rdir / "sfm")
    proxy = load_proxy(inputs.dense_ply, cfg.tour.proxy).transformed(s, R, t)
    sources = load_sources(pycolmap.Reconstruction(str(rdir / "sfm")), inputs.image_dir)
    ulr = UlrRenderer(proxy, sources, cfg.tour)
    ecfg = cfg.evaluate
    cam = Camera.pinhole(ecfg.validity_width, ecfg.validity_height, cfg.sim.camera.hfov_deg)
    return _Synthesis(ulr, cam, proxy, sources, s, n_common)


@dataclass
class _Truth:
    """The simulator's renderer of the true scene (no sensor noise) at round-frame poses.

    Attributes:
        to_world: similarity from round ``r``'s frame to the world.
        renderer: the :class:`~scenebot.sim.renderer.Renderer`.
        intr: its pinhole camera (the validity size).
    """

    to_world: object
    renderer: object
    intr: object

    def render(self, Rc: np.ndarray, tc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(image, depth) of the true scene from cam_from_world (Rc, tc) in round r's frame."""
        c_robot = -Rc.T @ tc
        c_world = self.to_world.apply(c_robot[None])[0]
        R_world = Rc @ self.to_world.R.T
        return self.renderer.render(self.intr, R_world, c_world, return_depth=True)


def _truth(cfg, inputs: ValidityInputs, rdir: Path, scene) -> _Truth:
    """The truth: round r's frame -> world, the simulator's renderer without sensor noise."""
    from scenebot.geometry import Intrinsics
    from scenebot.scene.loader import load_world_scene
    from scenebot.sim.renderer import Renderer

    to_world = robot_to_world(rdir / "sfm", inputs.captures)
    sc = scene if scene is not None else load_world_scene(cfg.world)
    cam_cfg = cfg.sim.camera
    w, h = cfg.evaluate.validity_width, cfg.evaluate.validity_height
    renderer = Renderer(sc, noise_sigma=0.0, antialias=cam_cfg.antialias)
    return _Truth(to_world, renderer, Intrinsics.from_hfov(w, h, cam_cfg.hfov_deg))


def _candidates_in_order(cfg, rdir: Path) -> tuple[dict, np.ndarray]:
    """Round r's scored candidates, and every usable one's index in a seeded random order."""
    from scenebot.artifacts.candidates import read_candidates

    cand_csv = rdir / "candidates.csv"
    if not cand_csv.is_file():
        raise EvaluationError(f"{cand_csv} not found: run the score stage of {rdir.name} first")
    cands = read_candidates(cand_csv)
    order = pick_candidates(
        cands, len(cands["score_deg"]), cfg.goals.min_hit_fraction, cfg.evaluate.seed
    )
    return cands, order


def _compare_views(
    cands: dict, order: np.ndarray, m: int, synth: _Synthesis, truth: _Truth, progress: bool
) -> tuple[list[dict], list[dict]]:
    """Synthesize and truly render the candidates in ``order`` until ``m`` have a true view.

    Returns:
        A row per compared candidate (:func:`_row`), and the candidates left out for want
        of a true view (index, true hit fraction, true median depth).
    """
    from tqdm import tqdm

    rows, excluded = [], []
    bar = tqdm(total=min(m, len(order)), desc="score validity", unit="view", disable=not progress)
    for i in order:
        if len(rows) >= m:
            break
        x, y, th = (float(cands[k][i]) for k in ("x", "y", "theta"))
        z, pitch = (float(cands[k][i]) if k in cands else 0.0 for k in ("z", "pitch"))
        Rc, tc = _candidate_pose(x, y, th, z, pitch)
        true, true_depth = truth.render(Rc, tc)
        hit = np.isfinite(true_depth)
        near = float(np.median(true_depth[hit])) if hit.any() else None
        if hit.mean() < MIN_TRUE_HIT or near is None or near < MIN_TRUE_DEPTH_M:
            # the map's free space put this pose inside, against or outside the true scene:
            # no view there to synthesize, so it says nothing about the score
            excluded.append({"index": int(i), "true_hit_fraction": float(hit.mean()),
                             "true_median_depth_m": near})  # fmt: skip
            continue
        res = synth.ulr.render(synth.cam, Rc, tc)
        bar.update()
        rows.append(_row(cands, i, (x, y, th), res, true))
    bar.close()
    return rows, excluded


def _row(cands: dict, i, pose: tuple[float, float, float], res, true: np.ndarray) -> dict:
    """One compared candidate: its pose and scores, and the quality of its ULR render."""
    from scenebot.tour.evaluate import psnr, ssim

    x, y, th = pose
    return {
        "index": int(i),
        "x": x,
        "y": y,
        "theta": th,
        "score_deg": float(cands["score_deg"][i]),
        "hit_fraction": float(cands["hit_fraction"][i]),
        "seen_fraction": float(cands["seen_fraction"][i]),
        "coverage": float(res.coverage),
        "psnr": min(psnr(res.image, true), PSNR_CAP_DB),
        "ssim": ssim(res.image, true),
    }


def _too_few_views(rows: list, excluded: list[dict], order: np.ndarray, rdir: Path):
    """The error for fewer than 3 candidates with a true view: why the others had none."""
    open_view = sum(e["true_hit_fraction"] < MIN_TRUE_HIT for e in excluded)
    return EvaluationError(
        f"only {len(rows)} of {len(order)} usable candidates of {rdir.name} have a true view: "
        f"{open_view} look mostly past the true scene (< {MIN_TRUE_HIT:.0%} of pixels on "
        f"it), {len(excluded) - open_view} stand against or inside it (median true depth "
        f"< {MIN_TRUE_DEPTH_M} m); too few for a correlation. The map of {rdir.name} "
        "disagrees with the truth there: see its sfm/accuracy.json and freespace.png"
    )


def _summary(
    rows: list[dict],
    excluded: list[dict],
    cands: dict,
    rdir: Path,
    inputs: ValidityInputs,
    synth: _Synthesis,
    ecfg,
    t0: float,
) -> dict:
    """The correlations of the score with the render quality, and what they rest on."""
    score = np.array([r["score_deg"] for r in rows])
    quality = np.array([r["psnr"] for r in rows])
    covered = np.array([r["coverage"] for r in rows]) >= 0.5
    lo, hi = bootstrap_interval(score, quality, seed=ecfg.seed)
    return {
        "round": rdir.name,
        "candidates": len(rows),
        "candidates_scored": int(np.isfinite(cands["score_deg"]).sum()),
        "candidates_examined": len(rows) + len(excluded),
        "spearman_score_psnr": spearman(score, quality),
        "spearman_95ci": [lo, hi],
        "spearman_score_ssim": spearman(score, [r["ssim"] for r in rows]),
        "spearman_seen_fraction_psnr": spearman([r["seen_fraction"] for r in rows], quality),
        "spearman_score_psnr_proxy_covered": spearman(score[covered], quality[covered]),
        "proxy_covered_candidates": int(covered.sum()),
        "excluded_no_true_view": excluded,
        "psnr_db": {"median": float(np.median(quality)), "mean": float(np.mean(quality))},
        "score_deg": {"median": float(np.median(score)), "max": float(np.max(score))},
        "size": [ecfg.validity_width, ecfg.validity_height],
        "proxy": {
            "dense": str(inputs.dense_ply),
            "points": len(synth.proxy),
            "to_round_frame_scale": synth.scale,
            "shared_photos": synth.shared_photos,
        },
        "sources": len(synth.sources),
        "seconds": time.perf_counter() - t0,
        "rows": rows,
    }


def run_validity(cfg, inputs: ValidityInputs, out_json: Path, out_png: Path | None = None,
                 progress: bool = True, scene=None) -> dict:  # fmt: skip
    """Score vs synthesized-view quality for random candidates of one round.

    Args:
        cfg: the campaign :class:`~scenebot.config.Config` (``sim``, ``world``, ``tour``,
            ``goals``, ``evaluate``).
        inputs: see :class:`ValidityInputs`.
        out_json: ``score_validity.json``.
        out_png: its scatter plot.
        progress: show a progress bar.
        scene: the true scene (None: loaded from ``cfg.world``).

    Returns:
        The summary written to ``out_json``.

    Raises:
        EvaluationError: missing inputs, too few candidates, or no true scene.
    """
    from scenebot.evaluate.stage import has_scene_truth

    ecfg = cfg.evaluate
    if not has_scene_truth(cfg):
        raise EvaluationError(
            f"robot {cfg.robot!r} has no true scene: score validity needs the simulator"
        )
    t0 = time.perf_counter()
    rdir = Path(inputs.round_dir)
    # every usable candidate in a seeded random order; the first M with a true view are kept
    cands, order = _candidates_in_order(cfg, rdir)
    synth = _synthesis(cfg, inputs, rdir)
    truth = _truth(cfg, inputs, rdir, scene)
    rows, excluded = _compare_views(cands, order, ecfg.validity_candidates, synth, truth, progress)
    if len(rows) < 3:
        raise _too_few_views(rows, excluded, order, rdir)
    summary = _summary(rows, excluded, cands, rdir, inputs, synth, ecfg, t0)
    out_json = Path(out_json)
    out_json.parent.mkdir(parents=True, exist_ok=True)
    out_json.write_text(json.dumps(summary, indent=1))
    if out_png is not None and ecfg.plots:
        plot_validity(summary, Path(out_png))
    lo, hi = summary["spearman_95ci"]
    LOG.info(
        "score validity (%s, %d views): Spearman(score, PSNR) = %.2f [%.2f, %.2f]",
        rdir.name, len(rows), summary["spearman_score_psnr"], lo, hi,
    )  # fmt: skip
    return summary


def plot_validity(summary: dict, png: Path) -> Path:
    """Scatter of PSNR against the heuristic score, coloured by the seen fraction."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = summary["rows"]
    score = np.array([r["score_deg"] for r in rows])
    q = np.array([r["psnr"] for r in rows])
    seen = np.array([r["seen_fraction"] for r in rows])
    fig, ax = plt.subplots(figsize=(6.4, 4.8), dpi=100)
    sc = ax.scatter(score, q, c=seen, cmap="viridis", vmin=0, vmax=1, s=18, edgecolors="none")
    fig.colorbar(sc, ax=ax, label="share of the view's mesh seen by a photo")
    fin = np.isfinite(q)
    if fin.sum() >= 2 and np.ptp(score[fin]) > 0:
        k, b = np.polyfit(score[fin], q[fin], 1)
        xs = np.linspace(score.min(), score.max(), 2)
        ax.plot(xs, k * xs + b, "k--", lw=1, label=f"least squares: {k:+.3f} dB/deg")
        ax.legend(loc="upper right")
    lo, hi = summary["spearman_95ci"]
    ax.set_xlabel("heuristic score: mean smallest photo angle (deg; high = poorly covered)")
    ax.set_ylabel("PSNR of the ULR render vs the true render (dB)")
    ax.set_title(
        f"{summary['round']}: {len(rows)} random candidates, Spearman rho = "
        f"{summary['spearman_score_psnr']:.2f} [{lo:.2f}, {hi:.2f}]",
        fontsize=10,
    )
    ax.grid(alpha=0.3)
    fig.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png)
    plt.close(fig)
    return png
