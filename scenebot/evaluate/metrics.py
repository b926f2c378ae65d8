"""Metrics of a round against the simulator's truth (evaluation only).

* :func:`robot_to_world`: the similarity that maps the map's robot frame onto the world frame,
  fitted (Umeyama, :func:`scenebot.sfm.evaluate.umeyama`) to the SfM camera centres and the
  capture logs' true centres. Nothing but the evaluation uses it.
* :func:`dense_metrics`: accuracy and completeness of a fused cloud at 1, 2, 5 cm against the
  true mesh and its observable surface, with area-weighted completeness (the samples of
  :mod:`scenebot.evaluate.observable` carry areas).
* :func:`capture_stats`: photos per round and goal outcomes from the capture logs.
* :func:`localization_accuracy`: visual-localization estimates logged with photos vs truth.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scenebot.capturelog import read_log
from scenebot.sfm.evaluate import summary_stats

GOAL_EVENTS = ("goal_reached", "goal_abandoned", "goal_skipped")


class EvaluationError(ValueError):
    """Inputs of the evaluation are missing or inconsistent; the message names the file."""


@dataclass
class Similarity:
    """``x_world = scale * R @ x_robot + t`` and its fit.

    Attributes:
        scale: world metres per map unit.
        R: (3, 3) rotation.
        t: (3,) translation (m).
        photos: photos the fit follows (:func:`scenebot.sfm.evaluate.robust_similarity`:
            those a decimetre off do not turn the frame).
        residual_m: statistics of every registered centre's distance to the true one (m).
    """

    scale: float
    R: np.ndarray
    t: np.ndarray
    photos: int
    residual_m: dict

    def apply(self, x: np.ndarray) -> np.ndarray:
        """Map (N, 3) robot-frame points to the world frame."""
        return self.scale * np.asarray(x, np.float64) @ self.R.T + self.t

    def as_dict(self) -> dict:
        return {
            "scale": self.scale,
            "R": self.R.tolist(),
            "t": self.t.tolist(),
            "photos": self.photos,
            "residual_m": self.residual_m,
        }


def _log_path(capture: Path) -> Path:
    capture = Path(capture)
    return capture / "log.jsonl" if capture.is_dir() else capture


def true_centers(captures: Sequence[Path]) -> dict[str, np.ndarray]:
    """Photo file name (basename) -> true camera centre (3,) from the logs' ``truth``."""
    out: dict[str, np.ndarray] = {}
    for cap in captures:
        path = _log_path(cap)
        if not path.is_file():
            raise EvaluationError(f"capture log {path} not found (run the capture stage first)")
        for rec in read_log(path):
            if rec.get("type") == "photo" and rec.get("truth", {}).get("center") is not None:
                out[Path(rec["image"]).name] = np.asarray(rec["truth"]["center"], np.float64)
    return out


def true_photo_poses(captures: Sequence[Path]) -> list[tuple[np.ndarray, np.ndarray]]:
    """(R_cam_from_world (3, 3), centre (3,)) of every photo with a true pose in the logs."""
    poses = []
    for cap in captures:
        for rec in read_log(_log_path(cap)):
            tr = rec.get("truth") or {}
            if rec.get("type") == "photo" and tr.get("R_cam_from_world") is not None:
                R = np.asarray(tr["R_cam_from_world"], np.float64)
                poses.append((R, np.asarray(tr["center"], np.float64)))
    return poses


def robot_to_world(sfm_dir: Path, captures: Sequence[Path]) -> Similarity:
    """Fit the robot-frame -> world similarity to the registered photos' true centres,
    robustly (:func:`scenebot.sfm.evaluate.robust_similarity`).

    Args:
        sfm_dir: a COLMAP model folder in the robot frame (``round_{r}/sfm``).
        captures: capture folders (or their ``log.jsonl``) of the photos in the model.

    Raises:
        EvaluationError: the model is missing, or fewer than 3 registered photos have truth.
    """
    import pycolmap

    from scenebot.sfm.evaluate import robust_similarity

    sfm_dir = Path(sfm_dir)
    if not (sfm_dir / "images.bin").is_file():
        raise EvaluationError(f"no COLMAP model in {sfm_dir} (images.bin missing)")
    rec = pycolmap.Reconstruction(str(sfm_dir))
    truth = true_centers(captures)
    est, tru = [], []
    for iid in rec.reg_image_ids():
        im = rec.image(iid)
        c = truth.get(Path(im.name).name)
        if c is not None:
            est.append(im.projection_center())
            tru.append(c)
    if len(est) < 3:
        raise EvaluationError(
            f"only {len(est)} registered photos of {sfm_dir} have a true pose in the capture "
            "logs (need 3): evaluation needs a simulated capture"
        )
    est, tru = np.array(est), np.array(tru)
    s, R, t, inl, res = robust_similarity(est, tru)
    return Similarity(float(s), R, t, int(inl.sum()), summary_stats(res))


def weighted_cloud_metrics(
    points: np.ndarray,
    vertices: np.ndarray,
    triangles: np.ndarray,
    reference: np.ndarray,
    weights: np.ndarray | None = None,
    *,
    thresholds_m: Sequence[float],
    return_distances: bool = False,
) -> dict[str, dict[str, float]] | tuple[dict[str, dict[str, float]], np.ndarray]:
    """Accuracy, area-weighted completeness and F-score of a cloud (world frame).

    Accuracy at tau: fraction of the cloud's points within tau of the true mesh (exact
    point-to-triangle distance, :func:`scenebot.dense.evaluate.mesh_raycaster`). Completeness
    at tau: fraction of the reference *area* (sum of ``weights``) whose samples have a cloud
    point within tau. Same layout as :func:`scenebot.dense.evaluate.cloud_metrics`, which
    this equals for uniform weights.

    Args:
        points: (N, 3) cloud (m).
        vertices: (V, 3) true mesh (m).
        triangles: (T, 3) indices.
        reference: (M, 3) samples of the observable surface (m).
        weights: (M,) their areas (m^2); None: uniform.
        thresholds_m: distances (m).
        return_distances: also return each reference sample's distance to the cloud.

    Returns:
        ``{"1cm": {"accuracy", "completeness", "fscore"}, ..., "median_error_m": {...}}``
        (and the (M,) distances with ``return_distances``).
    """
    import open3d as o3d
    from scipy.spatial import cKDTree

    from scenebot.dense.evaluate import mesh_raycaster

    points = np.asarray(points, np.float64)
    if len(points) == 0:
        raise EvaluationError("the dense point cloud is empty")
    if len(reference) == 0:
        raise EvaluationError("the observable surface has no samples")
    w = np.ones(len(reference)) if weights is None else np.asarray(weights, np.float64)
    rc = mesh_raycaster(vertices, triangles)
    d_acc = rc.compute_distance(o3d.core.Tensor(points.astype(np.float32))).numpy()
    d_comp, _ = cKDTree(points).query(reference, k=1, workers=-1)
    out: dict[str, dict[str, float]] = {}
    for tau in thresholds_m:
        a = float(np.mean(d_acc < tau))
        c = float(np.sum(w * (d_comp < tau)) / np.sum(w))
        f = 2 * a * c / (a + c) if a + c > 0 else 0.0
        out[f"{round(tau * 100, 1):g}cm"] = {"accuracy": a, "completeness": c, "fscore": f}
    order = np.argsort(d_comp)
    cw = np.cumsum(w[order])
    out["median_error_m"] = {
        "accuracy": float(np.median(d_acc)),
        "completeness": float(d_comp[order][np.searchsorted(cw, 0.5 * cw[-1])]),
    }
    return (out, d_comp) if return_distances else out


def read_cloud(path: Path, max_points: int, seed: int) -> np.ndarray:
    """(N, 3) points of a PLY cloud, randomly subsampled (``seed``: ``evaluate.seed``) to
    ``max_points`` (``evaluate.max_cloud_points``)."""
    import open3d as o3d

    path = Path(path)
    if not path.is_file():
        raise EvaluationError(f"dense cloud {path} not found (run the dense stage first)")
    pts = np.asarray(o3d.io.read_point_cloud(str(path)).points, np.float64)
    if len(pts) > max_points:
        pts = pts[np.random.default_rng(seed).choice(len(pts), max_points, replace=False)]
    return pts


def capture_stats(captures: Sequence[Path]) -> dict:
    """Photos per round and goal outcomes (events ``goal_reached``/``_abandoned``/``_skipped``).

    Args:
        captures: capture folders (or ``log.jsonl`` paths), one per round, in order.

    Returns:
        ``{"photos_per_round": [...], "photos_total", "goals_per_round": [{"reached", ...}],
        "goals": {"reached", "abandoned", "skipped", "attempted", "reached_fraction"},
        "has_truth": bool}``; rounds whose logs have no goal events count 0 (round 0 has none).
    """
    photos, goals, truth = [], [], False
    for cap in captures:
        path = _log_path(cap)
        if not path.is_file():
            raise EvaluationError(f"capture log {path} not found (run the capture stage first)")
        n = 0
        g = {e: 0 for e in GOAL_EVENTS}
        for rec in read_log(path):
            if rec.get("type") == "photo":
                n += 1
                truth |= "truth" in rec
            elif rec.get("type") == "event" and rec.get("event") in GOAL_EVENTS:
                g[rec["event"]] += 1
        photos.append(n)
        goals.append({k.removeprefix("goal_"): v for k, v in g.items()})
    tot = {k: sum(g[k] for g in goals) for k in ("reached", "abandoned", "skipped")}
    attempted = tot["reached"] + tot["abandoned"]
    tot["attempted"] = attempted
    tot["reached_fraction"] = tot["reached"] / attempted if attempted else None
    return {
        "photos_per_round": photos,
        "photos_total": int(sum(photos)),
        "goals_per_round": goals,
        "goals": tot,
        "has_truth": truth,
    }


def goal_truth(captures: Sequence[Path], sim: Similarity, reachable, reach_m: float = 0.10) -> dict:
    """Every goal of the adaptive rounds against the truth: could the robot get there, and
    how far from it did it truly stop.

    A goal is *reachable* when the robot position the robot drove to (``driven_goal``, map
    frame, moved to the world by ``sim``) lies in the free space connected to the start for
    the robot's footprint (``reachable``: world (x, y) -> bool). The position driven to is the
    one asked for (``robot_goal``) unless the planner moved it off a cell its map (or a bump)
    marks as an obstacle; the distance to the position asked for is reported beside it
    (``true_distance_to_asked_m``). Events without ``driven_goal`` (abandoned and skipped
    goals, older logs) use ``robot_goal``; events with neither count as unknown.

    Args:
        captures: capture folders (or logs) of rounds 0..r.
        sim: robot frame -> world similarity of the round's map (previous rounds' poses stay
            fixed in later maps, so every round's goals share its frame).
        reachable: predicate on a world (x, y).
        reach_m: a goal counts as reached when the robot truly stopped within this (m).

    Returns:
        ``{"goals": [per goal: round, index, event, reachable, true_distance_m,
        true_distance_to_asked_m, moved_m], "reachable", "reached_within",
        "reached_within_fraction_of_reachable", "reach_m", "true_distance_m",
        "true_distance_to_asked_m"}`` (summaries of the reached goals' true distances) and
        ``"reached_within_asked"`` (reachable goals truly within ``reach_m`` of the position
        asked for).
    """
    rows = []
    for r, cap in enumerate(captures):
        for rec in read_log(_log_path(cap)):
            if rec.get("type") != "event" or rec.get("event") not in GOAL_EVENTS:
                continue
            asked, driven = rec.get("robot_goal"), rec.get("driven_goal")
            g = driven if driven is not None else asked
            row = {"round": r, "index": rec.get("goal_index"), "event": rec["event"],
                   "reachable": None, "true_distance_m": None,
                   "true_distance_to_asked_m": None, "moved_m": None}  # fmt: skip
            if g is not None:
                gw = sim.apply(np.array([[float(g[0]), float(g[1]), 0.0]]))[0, :2]
                aw = gw
                if asked is not None:
                    aw = sim.apply(np.array([[float(asked[0]), float(asked[1]), 0.0]]))[0, :2]
                row["moved_m"] = float(np.hypot(*(gw - aw)))
                row["reachable"] = bool(reachable(gw))
                tr = rec.get("truth")
                if rec["event"] == "goal_reached" and tr is not None:
                    row["true_distance_m"] = float(math.hypot(tr["x"] - gw[0], tr["y"] - gw[1]))
                    row["true_distance_to_asked_m"] = float(
                        math.hypot(tr["x"] - aw[0], tr["y"] - aw[1])
                    )
            rows.append(row)
    reach = [x for x in rows if x["reachable"]]
    within = [
        x for x in reach if x["true_distance_m"] is not None and x["true_distance_m"] <= reach_m
    ]
    dists = [x["true_distance_m"] for x in rows if x["true_distance_m"] is not None]
    asked_d = [x["true_distance_to_asked_m"] for x in rows
               if x["true_distance_to_asked_m"] is not None]  # fmt: skip
    return {
        "goals": rows,
        "reachable": len(reach),
        "unknown": sum(1 for x in rows if x["reachable"] is None),
        "reached_within": len(within),
        "reached_within_fraction_of_reachable": len(within) / len(reach) if reach else None,
        "reach_m": reach_m,
        "true_distance_m": summary_stats(np.array(dists)) if dists else None,
        "reached_within_asked": sum(
            1
            for x in reach
            if x["true_distance_to_asked_m"] is not None
            and x["true_distance_to_asked_m"] <= reach_m
        ),
        "true_distance_to_asked_m": summary_stats(np.array(asked_d)) if asked_d else None,
    }


def _loc_error(loc: dict, tr: dict, sim: Similarity) -> tuple[float, float | None] | None:
    """(position error (m), heading error (rad) or None) of one map-frame estimate."""
    if "center" in loc and "center" in tr:
        est = sim.apply(np.asarray(loc["center"], float)[None])[0]
        err = float(np.linalg.norm(est - np.asarray(tr["center"], float)))
        h_err = None
        if "R_cam_from_world" in loc and "R_cam_from_world" in tr:
            # the camera's forward axis (row 2 of R_cam_from_world) in the world frame
            fe = sim.R @ np.asarray(loc["R_cam_from_world"], float).reshape(3, 3)[2]
            ft = np.asarray(tr["R_cam_from_world"], float).reshape(3, 3)[2]
            h_err = math.atan2(fe[1], fe[0]) - math.atan2(ft[1], ft[0])
        return err, h_err
    if {"x", "y"} <= loc.keys() and "robot" in tr:
        est = sim.apply(np.array([[loc["x"], loc["y"], 0.0]]))[0][:2]
        err = float(np.hypot(*(est - [tr["robot"]["x"], tr["robot"]["y"]])))
        h_err = None
        if "theta" in loc:
            h_err = loc["theta"] + math.atan2(sim.R[1, 0], sim.R[0, 0]) - tr["robot"]["theta"]
        return err, h_err
    return None


def _summary(errs: list[tuple[str, float, float | None]]) -> dict:
    if not errs:
        return {"count": 0}
    pos = np.array([e[1] for e in errs])
    head = np.array([abs(math.degrees(math.remainder(e[2], 2 * math.pi))) for e in errs
                     if e[2] is not None])  # fmt: skip
    return {
        "count": len(errs),
        "position_error_m": summary_stats(pos),
        "heading_error_deg": summary_stats(head),
        "per_estimate": [
            {"image": n, "position_error_m": p,
             "heading_error_deg": None if h is None
             else abs(math.degrees(math.remainder(h, 2 * math.pi)))}
            for n, p, h in errs
        ],
    }  # fmt: skip


def localization_accuracy(captures: Sequence[Path], sim: Similarity) -> dict:
    """Visual-localization estimates in the capture logs (map frame) against the true poses.

    Two kinds of records are read (adaptive rounds; see :mod:`scenebot.capture.adaptive`):

    * ``fixes``: events ``localize`` (a successful visual fix while following a path); their
      ``localization`` is a camera pose (``center``, ``R_cam_from_world``), compared with the
      event's ``truth`` camera pose: the paper's Fig. 5 localization accuracy.
    * ``photos``: photo records whose ``localization_source`` is ``this photo`` (or absent):
      the robot pose (``x``, ``y``, ``theta``) estimated from the photo, compared with
      ``truth.robot``.

    Estimates are mapped to the world with ``sim`` (robot frame -> world). Events
    ``localize_failed`` are counted, and ``localize_skipped`` (no photo taken: the map
    predicted too few matches, ``follow.min_matchable_points``).

    The fixes the robot turned away with a pose in hand are judged too (``turned_away``, per
    reason): ``localize_failed`` with a ``rejected_pose`` (``implausible_pose``,
    ``uncertain_pose``) and ``localize_rejected`` (against odometry or the compass), each
    with its error statistics and how many lay within :data:`RIGHT_FIX_M` of the truth (a
    right fix the checks cost the robot) or beyond :data:`WRONG_FIX_M` (a wrong one they
    kept out).

    Returns:
        ``{"fixes": {...}, "photos": {...}, "failed_fixes": n, "skipped_fixes": n,
        "turned_away": {reason: {...}}}``, the first two with ``count``,
        ``position_error_m`` / ``heading_error_deg`` statistics and ``per_estimate``.
    """
    fixes, photos, failed, skipped = [], [], 0, 0
    turned: dict[str, list] = {}
    for cap in captures:
        path = _log_path(cap)
        if not path.is_file():
            continue
        for rec in read_log(path):
            kind, event = rec.get("type"), rec.get("event")
            if kind == "event" and event in ("localize_failed", "localize_rejected"):
                failed += event == "localize_failed"
                _turned_away(rec, sim, turned)
                continue
            if kind == "event" and event == "localize_skipped":
                skipped += 1
                continue
            loc, tr = rec.get("localization"), rec.get("truth")
            if not isinstance(loc, dict) or not isinstance(tr, dict):
                continue
            if kind == "event" and event == "localize" and loc.get("ok", True):
                got, into = _loc_error(loc, tr, sim), fixes
            elif kind == "photo" and rec.get("localization_source", "this photo") == "this photo":
                got, into = _loc_error(loc, tr, sim), photos
            else:
                continue
            if got is not None:
                into.append((str(rec.get("image", "")), got[0], got[1]))
    return {
        "fixes": _summary(fixes),
        "photos": _summary(photos),
        "failed_fixes": failed,
        "skipped_fixes": skipped,
        "turned_away": {
            reason: _summary(errs)
            | {
                "right": sum(e[1] <= RIGHT_FIX_M for e in errs),
                "wrong": sum(e[1] > WRONG_FIX_M for e in errs),
            }
            for reason, errs in sorted(turned.items())
        },
    }


RIGHT_FIX_M = 0.05
"""A turned-away fix within this (m) of the truth was right (``turned_away`` ``right``)."""
WRONG_FIX_M = 0.25
"""A turned-away fix beyond this (m) of the truth was wrong (``turned_away`` ``wrong``)."""


def _turned_away(rec: dict, sim: Similarity, into: dict[str, list]) -> None:
    """Add a fix the robot did not use, where it had a pose, to ``into[reason]``: the pose a
    ``localize_failed`` judged (``rejected_pose``) or a ``localize_rejected``'s fix."""
    loc, tr = rec.get("localization"), rec.get("truth")
    if not isinstance(loc, dict) or not isinstance(tr, dict):
        return
    if rec.get("event") == "localize_rejected":
        pose, reason = loc, str(rec.get("reason", "rejected"))
    else:
        pose, reason = loc.get("rejected_pose"), str(loc.get("reason", "failed"))
    got = _loc_error(pose, tr, sim) if isinstance(pose, dict) else None
    if got is not None:
        into.setdefault(reason, []).append((str(rec.get("image", "")), got[0], got[1]))
