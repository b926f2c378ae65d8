"""The evaluate stage: one round's figures against the simulator's truth (evaluation only).

Entry points:

* :func:`run_observable` (rule ``observable``, once per scene): the observable surface of
  the true scene, ``results/{scene}/eval/observable_surface.npz`` + ``.png``.
* :func:`run` (rule ``evaluate``, per round): ``results/{scene}/round_{r}/evaluation.json``
  and ``evaluation.png`` with photos per round, goals reached, SfM accuracy (from
  ``round_{r}/sfm/accuracy.json``), visual-localization accuracy of logged estimates, and,
  when a dense cloud is given, its accuracy and completeness at 1, 2, 5 cm against the
  observable surface, where that completeness is lost (photographed or not, material) and
  the capture's coverage curve (observable area seen by >= 1 and >= 2 of the first n photos).

The true scene and poses are read only here; nothing a stage decides depends on them. For a
robot without truth (``nxt``, ``photos``, ``guided``) only the photo and goal counts are
written; a guided campaign adds its shots (``person_shots``: fulfilled, and with the simulated
person's truth how far from each shot it stood: :mod:`scenebot.evaluate.person`).
"""

from __future__ import annotations

import json
import logging
import math
import re
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scenebot.capturelog import json_default
from scenebot.evaluate.breakdown import (
    completeness_breakdown,
    count_views,
    coverage_by_photo_count,
    photo_visibility,
)
from scenebot.evaluate.config import EvaluateConfig
from scenebot.evaluate.metrics import (
    EvaluationError,
    capture_stats,
    goal_truth,
    localization_accuracy,
    read_cloud,
    robot_to_world,
    true_centers,
    true_photo_poses,
    weighted_cloud_metrics,
)

log = logging.getLogger(__name__)


@dataclass
class EvaluateInputs:
    """Inputs of one round's evaluation.

    Attributes:
        sfm_dir: the round's model folder ``round_{r}/sfm`` (robot frame), with
            ``accuracy.json`` when the sfm stage evaluated it.
        captures: capture folders (or ``log.jsonl`` files) of rounds 0..r, in order.
        dense_cloud: fused cloud (PLY, robot frame) to evaluate, or None.
        observable: the observable-surface cache (``eval/observable_surface.npz``); computed
            and written when missing or stale.
        round_index: the round; None: parsed from ``sfm_dir`` (``round_XXX``).
    """

    sfm_dir: Path
    captures: list[Path]
    dense_cloud: Path | None = None
    observable: Path | None = None
    round_index: int | None = None


@dataclass
class EvaluateOutputs:
    """``json``: ``round_{r}/evaluation.json``; ``png``: its picture (None: no picture)."""

    json: Path
    png: Path | None = None


@dataclass
class ObservableOutputs:
    """``npz``: the observable surface; ``png``: its top-down picture (None: none)."""

    npz: Path
    png: Path | None = None
    extra: dict = field(default_factory=dict)


def _evaluate_cfg(cfg, ecfg: EvaluateConfig | None) -> EvaluateConfig:
    if ecfg is not None:
        return ecfg
    got = getattr(cfg, "evaluate", None)
    return got if isinstance(got, EvaluateConfig) else EvaluateConfig()


def _scene(cfg, scene):
    if scene is not None:
        return scene
    from scenebot.scene.loader import load_world_scene

    return load_world_scene(cfg.world)


def has_scene_truth(cfg, ecfg: EvaluateConfig | None = None) -> bool:
    """Whether the true scene is known: a simulated robot, or photos taken in the configured
    world (``evaluate.reference_world``)."""
    if cfg.robot in ("sim", "nxt-emulated", "person-sim"):
        return True
    ecfg = _evaluate_cfg(cfg, ecfg)
    return cfg.robot == "photos" and ecfg.reference_world and ecfg.reference_cameras is not None


def run_observable(cfg, outputs: ObservableOutputs, ecfg: EvaluateConfig | None = None,
                   scene=None) -> dict:  # fmt: skip
    """Compute (or reuse the cached) observable surface of the campaign's simulated scene.

    Args:
        cfg: the campaign :class:`~scenebot.config.Config` (``world``, ``sim``).
        outputs: where to write it.
        ecfg: evaluation settings; None: ``cfg.evaluate`` if present, else defaults.
        scene: the true scene; None: loaded from ``cfg.world``.

    Returns:
        The summary (areas, counts, seconds) and where the surface came from
        (:meth:`~scenebot.evaluate.observable.Provenance.as_dict`: ``cached``, ``source``,
        ``key_hash``, ``cache_file``).

    Raises:
        EvaluationError: the campaign's robot has no simulated scene.
    """
    from scenebot.evaluate.observable import load_or_compute, plot_observable

    if not has_scene_truth(cfg, ecfg):
        raise EvaluationError(
            f"robot {cfg.robot!r} has no true scene: the observable surface needs the simulator "
            "(robot: sim or nxt-emulated, or robot: photos with evaluate.reference_world)"
        )
    ecfg = _evaluate_cfg(cfg, ecfg)
    t0 = time.perf_counter()
    sc = _scene(cfg, scene)
    surf, origin = load_or_compute(outputs.npz, sc, cfg.sim, ecfg, world_cfg=cfg.world)
    if outputs.png is not None and ecfg.plots:
        plot_observable(surf, outputs.png, f"scene {sc.name!r}: observable surface")
    return {**surf.summary(), **origin.as_dict(), "seconds": time.perf_counter() - t0}


def _reachable_test(cfg, sc):
    """World (x, y) -> whether the robot's centre can stand there, connected to the start."""
    from scenebot.evaluate.observable import collision_map, reachable_mask, start_pose

    cmap = collision_map(sc, cfg.sim)
    st = start_pose(sc, cfg.world, cmap)
    mask = reachable_mask(cmap, (st.x, st.y), cfg.sim.body.radius_m)

    def test(xy) -> bool:
        r, c = cmap._cell(xy)
        return bool(0 <= r < mask.shape[0] and 0 <= c < mask.shape[1] and mask[r, c])

    return test


def _round_of(sfm_dir: Path) -> int | None:
    for part in reversed(Path(sfm_dir).parts):
        m = re.fullmatch(r"round_(\d+)", part)
        if m:
            return int(m.group(1))
    return None


def _sfm_summary(sfm_dir: Path) -> dict | None:
    path = Path(sfm_dir) / "accuracy.json"
    if not path.is_file():
        return None
    acc = json.loads(path.read_text())
    return {k: v for k, v in acc.items() if k != "per_photo"} | {
        "per_photo_position_error_m": [p["position_error_m"] for p in acc.get("per_photo", [])],
        "per_photo_heading_error_deg": [p["heading_error_deg"] for p in acc.get("per_photo", [])],
    }


def run(
    cfg,
    inputs: EvaluateInputs,
    outputs: EvaluateOutputs,
    ecfg: EvaluateConfig | None = None,
    scene=None,
) -> dict:
    """Evaluate one round and write ``evaluation.json`` (+ PNG).

    Args:
        cfg: the campaign :class:`~scenebot.config.Config` (``robot``, ``world``, ``sim``).
        inputs: see :class:`EvaluateInputs`.
        outputs: see :class:`EvaluateOutputs`.
        ecfg: evaluation settings; None: ``cfg.evaluate`` if present, else defaults.
        scene: the true scene; None: loaded from ``cfg.world`` (simulated robots only).

    Returns:
        What ``evaluation.json`` holds: ``round``, ``capture`` (photos per round, goals),
        ``sfm`` (accuracy summary or None), ``alignment`` (robot frame -> world),
        ``localization``, ``observable`` (areas), ``dense`` (metrics per threshold or None),
        ``coverage_by_photos`` (with the dense cloud: ``photos``, ``seen_1``, ``seen_2``,
        :func:`~scenebot.evaluate.breakdown.coverage_by_photo_count`, or None), ``notes``.
    """
    from scenebot.evaluate.observable import load_or_compute

    ecfg = _evaluate_cfg(cfg, ecfg)
    t0 = time.perf_counter()
    r = inputs.round_index if inputs.round_index is not None else _round_of(inputs.sfm_dir)
    caps = [Path(c) for c in inputs.captures]
    stats = capture_stats(caps)
    out: dict = {
        "round": r,
        "scene": getattr(cfg, "scene", None),
        "capture": stats,
        "sfm": _sfm_summary(inputs.sfm_dir),
        "alignment": None,
        "localization": None,
        "goals_truth": None,
        "observable": None,
        "dense": None,
        "coverage_by_photos": None,
        "notes": [],
    }
    cams = stats["has_truth"]  # true camera poses: a simulated capture, or reference cameras
    truth = has_scene_truth(cfg, ecfg) and cams  # and the true scene
    if not cams:
        out["notes"].append("no true poses in the capture logs: truth-based metrics skipped")
    sim = None
    if cams:
        try:
            sim = robot_to_world(inputs.sfm_dir, caps)
            out["alignment"] = sim.as_dict()
            if truth:
                out["localization"] = localization_accuracy(caps, sim)
                sc = _scene(cfg, scene)
                out["goals_truth"] = goal_truth(caps, sim, _reachable_test(cfg, sc))
        except EvaluationError as exc:
            out["notes"].append(str(exc))
    if cfg.robot == "photos" and cams:
        out["reference"] = _reference_summary(inputs.sfm_dir, caps, sim)
    if cfg.robot in ("guided", "person-sim") and r:  # the guide's shots, fulfilled and truly
        from scenebot.evaluate.person import person_shots

        out["person_shots"] = person_shots(Path(inputs.sfm_dir).parents[1], caps, r)
    surf = cloud = None
    if sim is not None and not truth and inputs.dense_cloud is not None:
        if ecfg.reference_bbox is not None:
            cloud = sim.apply(read_cloud(inputs.dense_cloud, ecfg.max_cloud_points, ecfg.seed))
            out["dense"] = {
                "cloud": str(inputs.dense_cloud),
                "points": len(cloud),
                **bbox_share(cloud, np.asarray(ecfg.reference_bbox)),
            }
        else:
            out["notes"].append("no true scene: the dense cloud is not evaluated")
    if truth and inputs.dense_cloud is not None:
        if sim is None:
            out["notes"].append("dense cloud not evaluated: no robot->world alignment")
        else:
            sc = _scene(cfg, scene)
            surf, origin = load_or_compute(
                inputs.observable, sc, cfg.sim, ecfg, world_cfg=cfg.world
            )
            obs_file = str(inputs.observable) if inputs.observable else None
            out["observable"] = {**surf.summary(), **origin.as_dict(), "file": obs_file}
            cloud = sim.apply(read_cloud(inputs.dense_cloud, ecfg.max_cloud_points, ecfg.seed))
            m, d_comp = weighted_cloud_metrics(
                cloud, sc.vertices, sc.triangles, surf.observable_points,
                surf.observable_weights, thresholds_m=ecfg.thresholds_m, return_distances=True,
            )  # fmt: skip
            out["dense"] = {"cloud": str(inputs.dense_cloud), "points": len(cloud), **m}
            # one visibility render per photo, in capture order: the view counts of the
            # breakdown and the coverage after the first n photos
            vis = list(photo_visibility(
                surf.observable_points, true_photo_poses(caps), sc, cfg.sim.camera.hfov_deg
            ))  # fmt: skip
            views = count_views(vis, len(surf.observable_points))
            out["coverage_by_photos"] = coverage_by_photo_count(vis, surf.observable_weights)
            out["dense"]["breakdown"] = completeness_breakdown(
                d_comp, surf.observable_weights, views,
                sc.material_ids[surf.triangle[surf.observable]], sc.materials, ecfg.thresholds_m,
            )  # fmt: skip
            dense_dir = Path(inputs.dense_cloud).parent
            if ecfg.depth_maps and (dense_dir / "stereo").is_dir():
                from scenebot.evaluate.depthmaps import evaluate_depth_maps

                out["dense"]["depth_maps"] = evaluate_depth_maps(
                    dense_dir, sim, sc, ecfg.depth_rel_tol, ecfg.depth_map_views
                )
    elif inputs.dense_cloud is None:
        out["notes"].append("no dense cloud given: dense metrics skipped")
    out["seconds"] = time.perf_counter() - t0
    outputs.json.parent.mkdir(parents=True, exist_ok=True)
    outputs.json.write_text(json.dumps(out, indent=1, default=json_default) + "\n")
    if outputs.png is not None and ecfg.plots:
        plot_evaluation(out, outputs.png, surf, cloud)
    return out


def bbox_share(cloud: np.ndarray, box: np.ndarray) -> dict:
    """Share of the points inside the box ``[[x0, y0, z0], [x1, y1, z1]]``, and inside it
    grown by a tenth of its diagonal (points on the object's support or just off it)."""
    margin = 0.1 * float(np.linalg.norm(box[1] - box[0]))
    inside = np.all((cloud >= box[0]) & (cloud <= box[1]), axis=1)
    near = np.all((cloud >= box[0] - margin) & (cloud <= box[1] + margin), axis=1)
    n = max(len(cloud), 1)
    return {
        "bbox": box.tolist(),
        "inside_bbox": float(inside.sum() / n),
        "near_bbox": float(near.sum() / n),
        "near_margin": margin,
    }


def _reference_summary(sfm_dir: Path, caps: list[Path], sim) -> dict:
    """robot: photos with reference cameras: how many there are, how many the map
    registered, and the camera-centre errors after the similarity fit (reference units)."""
    import pycolmap

    ref = true_centers(caps)
    rec = pycolmap.Reconstruction(str(sfm_dir))
    names = {Path(rec.image(i).name).name for i in rec.reg_image_ids()}
    out = {
        "cameras": len(ref),
        "registered": len(names & ref.keys()),
        "not_registered": sorted(ref.keys() - names),
        "note": "camera-centre errors after a robust similarity fit, in the reference's units",
    }
    if sim is not None:
        out["centre_error"] = sim.residual_m
        out["fit_photos"] = sim.photos
    return out


def plot_evaluation(ev: dict, png: Path, surf=None, cloud: np.ndarray | None = None) -> Path:
    """The round's picture: SfM error histograms (paper Fig. 5b style), photos and goals per
    round, dense accuracy/completeness per threshold, and a top-down completeness map."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    depth_maps = (ev.get("dense") or {}).get("depth_maps")
    rows = 3 if depth_maps else 2
    fig, axes = plt.subplots(rows, 3, figsize=(18, 4.5 * rows), dpi=100)
    sfm = ev.get("sfm") or {}
    ax = axes[0, 0]
    pe = np.array(sfm.get("per_photo_position_error_m", [])) * 100
    if pe.size:
        ax.hist(pe, bins=30, color="tab:blue", alpha=0.8)
        ax.axvline(np.median(pe), color="k", ls="--", label=f"median {np.median(pe):.2f} cm")
        ax.legend()
    else:
        ax.text(0.5, 0.5, "no SfM accuracy (accuracy.json)", ha="center", transform=ax.transAxes)
    ax.set_xlabel("camera position error (cm)")
    ax.set_ylabel("photos")
    ax.set_title(f"SfM accuracy, round {ev.get('round')}: {sfm.get('evaluated', 0)} photos")
    ax = axes[0, 1]
    cap = ev["capture"]
    rounds = np.arange(len(cap["photos_per_round"]))
    ax.bar(rounds - 0.2, cap["photos_per_round"], 0.4, label="photos", color="tab:gray")
    ax.set_xlabel("round")
    ax.set_ylabel("photos")
    ax2 = ax.twinx()
    g = cap["goals_per_round"]
    ax2.bar(rounds + 0.2, [x["reached"] for x in g], 0.4, color="tab:green", label="goals reached")
    ax2.bar(rounds + 0.2, [x["abandoned"] for x in g], 0.4, bottom=[x["reached"] for x in g],
            color="tab:red", label="abandoned")  # fmt: skip
    ax2.set_ylabel("goals")
    h1, l1 = ax.get_legend_handles_labels()
    h2, l2 = ax2.get_legend_handles_labels()
    ax.legend(h1 + h2, l1 + l2, loc="upper right")
    ax.set_xticks(rounds)
    ax.set_title(f"capture: {cap['photos_total']} photos in all")
    ax = axes[1, 0]
    dense = ev.get("dense")
    if dense:
        taus = [k for k in dense if k.endswith("cm")]
        x = np.arange(len(taus))
        acc = [100 * dense[k]["accuracy"] for k in taus]
        comp = [100 * dense[k]["completeness"] for k in taus]
        ax.bar(x - 0.2, acc, 0.4, label="accuracy")
        ax.bar(x + 0.2, comp, 0.4, label="completeness (observable area)")
        for xi, a, c in zip(x, acc, comp, strict=True):
            ax.text(xi - 0.2, a + 1, f"{a:.1f}", ha="center", fontsize=8)
            ax.text(xi + 0.2, c + 1, f"{c:.1f}", ha="center", fontsize=8)
        ax.set_xticks(x, taus)
        ax.set_ylim(0, 105)
        ax.set_ylabel("%")
        ax.legend(loc="lower right")
        ax.set_title(f"dense cloud: {dense['points']} points")
    else:
        ax.text(0.5, 0.5, "no dense cloud evaluated", ha="center", transform=ax.transAxes)
        ax.set_axis_off()
    ax = axes[1, 1]
    if surf is not None and cloud is not None and len(cloud):
        from scipy.spatial import cKDTree

        p = surf.observable_points
        d, _ = cKDTree(cloud).query(p, k=1, distance_upper_bound=0.1, workers=-1)
        order = np.argsort(p[:, 2])  # higher surfaces drawn last
        sc = ax.scatter(p[order, 0], p[order, 1], c=np.minimum(d[order], 0.1) * 100, s=0.3,
                        cmap="RdYlGn_r", vmin=0, vmax=5, lw=0)  # fmt: skip
        fig.colorbar(sc, ax=ax, fraction=0.04, label="distance to the cloud (cm)")
        ax.set_aspect("equal")
        ax.set_title("observable surface, top-down: distance to the nearest cloud point")
        ax.set_xlabel("x (m, world)")
    else:
        ax.set_axis_off()
    _plot_breakdown(axes[0, 2], axes[1, 2], (dense or {}).get("breakdown"))
    if depth_maps:
        _plot_depth_maps(axes[2, 0], axes[2, 1], axes[2, 2], depth_maps)
    fig.tight_layout()
    png = Path(png)
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png)
    plt.close(fig)
    return png


def _plot_depth_maps(ax_views, ax_mat, ax_text, dm: dict, top: int = 8) -> None:
    """Per view: share of the pixels with a depth against the share of those right, for the
    measured and the final maps, with the issue's bars; by material for the final maps."""
    from scenebot.evaluate.depthmaps import COVERAGE_BAR, WITHIN_BAR

    tol = None
    for kind, color in (("measured", "tab:gray"), ("final", "tab:orange")):
        pts = [(r[kind]["coverage"], r[kind]["accuracy"]) for r in dm["views"] if r.get(kind)]
        if pts:
            c, a = np.array(pts).T * 100
            ax_views.scatter(c, a, s=8, color=color, label=f"{kind} ({len(pts)} views)")
        tol = (dm["summary"].get(kind) or {}).get("bars", {}).get("rel_tol", tol)
    ax_views.axvline(100 * COVERAGE_BAR, color="k", ls=":", lw=1)
    ax_views.axhline(100 * WITHIN_BAR, color="k", ls=":", lw=1)
    ax_views.set_xlim(0, 100)
    ax_views.set_ylim(0, 100)
    ax_views.set_xlabel("pixels with a depth (%)")
    ax_views.set_ylabel(f"of those within {100 * (tol or 0.02):g}% of the true depth (%)")
    ax_views.legend(loc="lower left", fontsize=8)
    ax_views.set_title("depth maps, view by view (bars dotted)")
    rows = (dm["by_material"].get("final") or [])[:top][::-1]
    y = np.arange(len(rows))
    ax_mat.barh(y + 0.2, [100 * r["with_depth"] for r in rows], 0.4, color="tab:orange",
                label="pixels with a depth")  # fmt: skip
    ax_mat.barh(y - 0.2, [100 * (r["within"] or 0) for r in rows], 0.4, color="tab:green",
                label="of those right")  # fmt: skip
    ax_mat.set_yticks(y, [f"{r['material']} ({100 * r['pixel_share']:.0f}% of pixels)"
                          for r in rows], fontsize=8)  # fmt: skip
    ax_mat.set_xlim(0, 105)
    ax_mat.legend(loc="lower right", fontsize=8)
    ax_mat.set_title("final depth maps by material")
    lines = []
    for kind, s in dm["summary"].items():
        if not s:
            continue
        wk = next(k for k in s if k.startswith("within_") and k.endswith("_median"))
        lines.append(
            f"{kind}: {s['views']} views\n  pixels with a depth: median "
            f"{100 * s['coverage_median']:.1f}%\n  of those right: median "
            f"{100 * s[wk]:.1f}%\n  views meeting both bars: {s['views_meeting_bars']}"
        )
    ax_text.text(0.02, 0.98, "\n\n".join(lines), va="top", family="monospace", fontsize=10,
                 transform=ax_text.transAxes)  # fmt: skip
    ax_text.set_axis_off()


def _plot_breakdown(ax_mat, ax_views, b: dict | None, tau: str = "2cm", top: int = 10) -> None:
    """Completeness by material (largest areas) and by the number of photos that saw it."""
    if not b:
        for ax in (ax_mat, ax_views):
            ax.text(0.5, 0.5, "no completeness breakdown", ha="center", transform=ax.transAxes)
            ax.set_axis_off()
        return
    rows = b["by_material"][:top][::-1]
    y = np.arange(len(rows))
    comp = [100 * (r["completeness"].get(tau) or 0) for r in rows]
    seen = [100 * r["photographed_share"] for r in rows]
    ax_mat.barh(y + 0.2, seen, 0.4, color="tab:gray", label="seen by >= 2 photos")
    ax_mat.barh(y - 0.2, comp, 0.4, color="tab:orange", label=f"complete at {tau}")
    labels = [
        f"{r['material']} ({100 * r['area_share']:.0f}%, contrast {r['texture_contrast']:.0f})"
        for r in rows
    ]
    ax_mat.set_yticks(y, labels, fontsize=8)
    ax_mat.set_xlim(0, 105)
    ax_mat.set_xlabel("% of the material's observable area")
    ax_mat.legend(loc="lower right", fontsize=8)
    ax_mat.set_title("by material (share of the area, texture contrast)")
    cls = b["by_views"]
    x = np.arange(len(cls))
    ax_views.bar(x - 0.2, [100 * c["area_share"] for c in cls], 0.4, color="tab:gray",
                 label="share of the observable area")  # fmt: skip
    ax_views.bar(x + 0.2, [100 * (c["completeness"].get(tau) or 0) for c in cls], 0.4,
                 color="tab:orange", label=f"complete at {tau}")  # fmt: skip
    ax_views.set_xticks(x, [c["views"] for c in cls])
    ax_views.set_xlabel("photos that see the surface")
    ax_views.set_ylim(0, 105)
    ax_views.set_ylabel("%")
    ax_views.legend(loc="upper left", fontsize=8)
    ax_views.set_title("lost in capture (0-1 photos) or in stereo (>= 2)")


def main_summary(ev: dict) -> str:
    """One line per figure, for logs and the CLI."""
    lines = [f"round {ev['round']}: {ev['capture']['photos_total']} photos"]
    g = ev["capture"]["goals"]
    if g["attempted"]:
        lines.append(f"goals reached {g['reached']}/{g['attempted']}")
    gt = ev.get("goals_truth") or {}
    if gt.get("reachable"):
        lines.append(
            f"truly reachable goals reached within {100 * gt['reach_m']:.0f} cm "
            f"{gt['reached_within']}/{gt['reachable']}"
        )
    if ev.get("sfm") and "position_error_m" in ev["sfm"]:
        lines.append(
            f"sfm median position error {100 * ev['sfm']['position_error_m']['median']:.2f} cm"
        )
    fixes = (ev.get("localization") or {}).get("fixes", {})
    if fixes.get("count"):
        med = 100 * fixes["position_error_m"]["median"]
        lines.append(f"{fixes['count']} visual fixes, median error {med:.2f} cm")
    away = (ev.get("localization") or {}).get("turned_away") or {}
    if away:
        lines.append(
            "fixes turned away: " + ", ".join(
                f"{r} {v['count']} ({v['right']} right, {v['wrong']} wrong)"
                for r, v in away.items()
            )
        )  # fmt: skip
    if ev.get("dense"):
        d = ev["dense"]
        lines.append(
            "dense " + ", ".join(
                f"{k}: acc {100 * v['accuracy']:.1f}% comp {100 * v['completeness']:.1f}%"
                for k, v in d.items() if k.endswith("cm")
            )
        )  # fmt: skip
        b = d.get("breakdown")
        if b:
            where = b["completeness_where_photographed"].get("2cm")
            lines.append(
                f"{100 * b['photographed_share']:.0f}% of the observable area seen by >= 2 "
                f"photos, {100 * (where or 0):.0f}% of it complete at 2 cm"
            )
        fin = ((d.get("depth_maps") or {}).get("summary") or {}).get("final")
        if fin:
            wk = next(k for k in fin if k.startswith("within_") and k.endswith("_median"))
            lines.append(
                f"final depth maps: median {100 * fin['coverage_median']:.0f}% of the pixels "
                f"with a depth, {100 * fin[wk]:.0f}% of those right; "
                f"{fin['views_meeting_bars']}/{fin['views']} views meet both bars"
            )
    if not math.isnan(ev.get("seconds", float("nan"))):
        lines.append(f"({ev['seconds']:.1f} s)")
    return "; ".join(lines)
