"""Accuracy of the map against the simulator's true poses (paper section V.B, Fig. 5b).

A similarity transform (Umeyama, least squares) maps the SfM camera centres onto the true
centres; the position error of each photo is split along the true line of sight and
transverse to it (stereo is least accurate along the line of sight); the heading error is
the difference of the viewing directions' yaw after the similarity's rotation. Because the
model is meant to be metric, the similarity's scale is also the metric scale error.
Truth is read only here, for evaluation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import pycolmap

from scenebot.geometry import rotation_angle_deg

M_PER_INCH = 0.0254


def umeyama(src: np.ndarray, dst: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Least-squares similarity ``dst ~ s * R @ src + t`` (Umeyama 1991).

    Args:
        src, dst: (N, 3) corresponding points, N >= 3 not collinear.

    Returns:
        ``s`` (float), ``R`` (3, 3) proper rotation, ``t`` (3,).
    """
    mu_s, mu_d = src.mean(0), dst.mean(0)
    xs, xd = src - mu_s, dst - mu_d
    cov = xd.T @ xs / len(src)
    U, D, Vt = np.linalg.svd(cov)
    S = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        S[2, 2] = -1
    R = U @ S @ Vt
    var_s = (xs**2).sum() / len(src)
    s = float(np.trace(np.diag(D) @ S) / var_s)
    t = mu_d - s * R @ mu_s
    return s, R, t


def summary_stats(x: np.ndarray) -> dict[str, float]:
    """Median, mean, 90th percentile and maximum of ``x`` (empty: ``{}``)."""
    x = np.asarray(x, np.float64)
    if x.size == 0:
        return {}
    return {
        "median": float(np.median(x)),
        "mean": float(np.mean(x)),
        "p90": float(np.percentile(x, 90)),
        "max": float(np.max(x)),
    }


GROSS_FACTOR = 10.0  # a photo this many median errors off (and > GROSS_MIN_M) is a gross error
GROSS_MIN_M = 0.25
FIT_MIN_M = 0.05  # photos farther off than this (and GROSS_FACTOR medians) do not steer the fit


def _refit(
    src: np.ndarray, dst: np.ndarray, inl: np.ndarray, factor: float, min_m: float, iterations: int
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Umeyama on ``inl``, then keep the points within ``max(factor * median inlier
    residual, min_m)`` and refit, until the set stops changing."""
    s, R, t = umeyama(src[inl], dst[inl])
    d = np.linalg.norm(s * src @ R.T + t - dst, axis=1)
    for _ in range(iterations):
        new = d <= max(factor * float(np.median(d[inl])), min_m)
        if new.sum() < 3 or np.array_equal(new, inl):
            break
        inl = new
        s, R, t = umeyama(src[inl], dst[inl])
        d = np.linalg.norm(s * src @ R.T + t - dst, axis=1)
    return s, R, t, inl, d


def _least_median_inliers(
    src: np.ndarray, dst: np.ndarray, samples: int, seed: int
) -> np.ndarray | None:
    """Least median of squares over random minimal sets (3 points): the half of the points
    nearest to the best sample's similarity, or None for fewer than 6 points."""
    n = len(src)
    if n < 6:
        return None
    rng = np.random.default_rng(seed)
    best, best_d = np.inf, None
    for _ in range(samples):
        idx = rng.choice(n, 3, replace=False)
        a, b, c = src[idx]
        if np.linalg.norm(np.cross(b - a, c - a)) < 1e-9:
            continue  # collinear: no rotation about their line
        s, R, t = umeyama(src[idx], dst[idx])
        d = np.linalg.norm(s * src @ R.T + t - dst, axis=1)
        med = float(np.median(d))
        if med < best:
            best, best_d = med, d
    if best_d is None:
        return None
    return best_d <= np.median(best_d)


def robust_similarity(
    src: np.ndarray,
    dst: np.ndarray,
    factor: float = GROSS_FACTOR,
    min_m: float = FIT_MIN_M,
    iterations: int = 10,
    samples: int = 300,
    seed: int = 0,
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Similarity ``dst ~ s * R @ src + t`` fitted to the points that agree with it.

    Iteratively re-weighted in the simplest way: fit (Umeyama) to the current inliers, keep
    the points within ``max(factor * median residual, min_m)``, repeat until the set stops
    changing. A few photos registered 10-40 cm off would otherwise turn the whole frame
    (0.4 deg over a 5 m room, i.e. centimetres at the walls) and every error measured through
    it; they are still reported with their residuals, they just do not steer the fit.

    Two starts, the fit with the smaller median residual over all points kept: all points,
    and least median of squares over ``samples`` random triples (deterministic, ``seed``).
    Started from all points alone, a sixth of the photos registered 1-3 m off (a folded
    round in the flat) pulled the fit of planar cameras into its mirror image (frame tilted
    179 deg, headings off by 90 deg in the median), and the refit never left it.

    Args:
        src, dst: (N, 3) corresponding points, N >= 3.
        factor, min_m: inlier threshold, ``max(factor * median inlier residual, min_m)`` (m).
        iterations: at most this many refits.
        samples, seed: random triples of the least-median start, and their generator's seed.

    Returns:
        ``s``, ``R`` (3, 3), ``t`` (3,), the inlier mask of the fit and the residuals (m) of
        every point.
    """
    src, dst = np.asarray(src, np.float64), np.asarray(dst, np.float64)
    starts = [np.ones(len(src), bool)]
    lmeds = _least_median_inliers(src, dst, samples, seed)
    if lmeds is not None and lmeds.sum() >= 3:
        starts.append(lmeds)
    fits = [_refit(src, dst, inl, factor, min_m, iterations) for inl in starts]
    return min(fits, key=lambda f: float(np.median(f[4])))


@dataclass
class _TruthPairs:
    """Registered photos with a true pose: estimated and true camera centres (N, 3),
    viewing directions (3,) and rotations (3, 3) (cam_from_world)."""

    names: list[str]
    est_c: np.ndarray
    true_c: np.ndarray
    est_v: list[np.ndarray]
    true_v: list[np.ndarray]
    est_r: list[np.ndarray]
    true_r: list[np.ndarray]

    def subset(self, keep: np.ndarray) -> _TruthPairs:
        """The photos at indices ``keep``."""
        return _TruthPairs(
            [self.names[i] for i in keep],
            self.est_c[keep],
            self.true_c[keep],
            [self.est_v[i] for i in keep],
            [self.true_v[i] for i in keep],
            [self.est_r[i] for i in keep],
            [self.true_r[i] for i in keep],
        )


class _Errors(NamedTuple):
    """Per-photo errors: position (m) in total, along the true line of sight and transverse
    to it, heading and rotation (deg)."""

    total: np.ndarray
    los: np.ndarray
    transverse: np.ndarray
    heading: np.ndarray
    rotation: np.ndarray


def _truth_pairs(rec: pycolmap.Reconstruction, truths: dict[str, dict]) -> _TruthPairs:
    """The registered photos of ``rec`` that have a complete ``truth`` record."""
    names, est_c, est_v, true_c, true_v, true_r, est_r = [], [], [], [], [], [], []
    for iid in rec.reg_image_ids():
        im = rec.image(iid)
        tr = truths.get(im.name)
        if not tr or "center" not in tr or "R_cam_from_world" not in tr:
            continue
        R_est = im.cam_from_world().rotation.matrix()
        R_true = np.asarray(tr["R_cam_from_world"], float).reshape(3, 3)
        names.append(im.name)
        est_c.append(im.projection_center())
        est_v.append(R_est[2])
        est_r.append(R_est)
        true_c.append(np.asarray(tr["center"], float))
        true_v.append(R_true[2])
        true_r.append(R_true)
    return _TruthPairs(names, np.array(est_c), np.array(true_c), est_v, true_v, est_r, true_r)


def _pose_errors(pairs: _TruthPairs, s: float, R: np.ndarray, t: np.ndarray) -> _Errors:
    """The errors of the estimated poses mapped by the similarity ``(s, R, t)``."""
    mapped = s * pairs.est_c @ R.T + t
    err = mapped - pairs.true_c
    tv = np.array(pairs.true_v)
    los = np.abs((err * tv).sum(1))
    transverse = np.linalg.norm(err - (err * tv).sum(1, keepdims=True) * tv, axis=1)
    total = np.linalg.norm(err, axis=1)
    ev = np.array(pairs.est_v) @ R.T
    yaw_e = np.arctan2(ev[:, 1], ev[:, 0])
    yaw_t = np.arctan2(tv[:, 1], tv[:, 0])
    heading = np.degrees(np.abs((yaw_e - yaw_t + np.pi) % (2 * np.pi) - np.pi))
    rot_err = []
    for Re, Rt in zip(pairs.est_r, pairs.true_r, strict=True):
        # camera orientation in the true world: R_cam_from_world_est @ R^T
        dR = (Re @ R.T) @ Rt.T
        rot_err.append(rotation_angle_deg(dR))
    return _Errors(total, los, transverse, heading, np.array(rot_err))


def _frame_tilt_and_yaw(R: np.ndarray) -> tuple[float, float]:
    """Tilt between the robot frame's z and the world's z, and the robot frame's yaw (deg)."""
    z_in_world = R @ np.array([0.0, 0.0, 1.0])
    tilt = math.degrees(math.acos(np.clip(z_in_world[2], -1, 1)))
    x_in_world = R @ np.array([1.0, 0.0, 0.0])
    frame_yaw = math.degrees(math.atan2(x_in_world[1], x_in_world[0]))
    return tilt, frame_yaw


def evaluate_accuracy(rec: pycolmap.Reconstruction, truths: dict[str, dict]) -> dict:
    """Accuracy of the registered cameras against true poses.

    Args:
        rec: the model (robot frame).
        truths: photo name -> ``truth`` record of the capture log (``center`` (3,) m,
            ``R_cam_from_world`` 9 row-major).

    Returns:
        The content of ``accuracy.json``: per-photo errors and summaries in metres, inches,
        centimetres and degrees, the similarity, and the metric scale error.
    """
    pairs = _truth_pairs(rec, truths)
    if len(pairs.names) < 3:
        return {"evaluated": len(pairs.names), "note": "fewer than 3 registered photos with truth"}
    # Robust similarity: photos registered grossly wrong (repeated textures can place a few
    # photos metres off) are reported apart and kept out of the statistics; those a few
    # centimetres to decimetres off stay in the statistics but do not steer the fit.
    s, R, t, fit_inl, d = robust_similarity(pairs.est_c, pairs.true_c)
    gross_m = max(GROSS_FACTOR * float(np.median(d[fit_inl])), GROSS_MIN_M)
    inl = d <= gross_m
    gross = [(pairs.names[i], float(d[i])) for i in np.flatnonzero(~inl)]
    pairs = pairs.subset(np.flatnonzero(inl))
    e = _pose_errors(pairs, s, R, t)
    tilt, frame_yaw = _frame_tilt_and_yaw(R)
    return {
        "evaluated": len(pairs.names),
        "registered": rec.num_reg_images(),
        "gross_errors": {
            "count": len(gross),
            "threshold_m": gross_m,
            "photos": {n: round(err, 3) for n, err in gross},
            "note": "registered farther than threshold_m from the truth after the robust "
            "similarity; left out of the statistics",
        },
        "similarity": {
            "scale": s,
            "R": R.tolist(),
            "t": t.tolist(),
            "fitted_photos": int(fit_inl.sum()),
            "note": "fitted to the photos within max(10 median residuals, 5 cm) of the truth",
        },
        "metric_scale_error": abs(1.0 / s - 1.0),
        "frame_tilt_deg": tilt,
        "frame_yaw_in_world_deg": frame_yaw,
        "position_error_m": summary_stats(e.total),
        "line_of_sight_error_m": summary_stats(e.los),
        "transverse_error_m": summary_stats(e.transverse),
        "position_error_cm": summary_stats(e.total * 100),
        "position_error_in": summary_stats(e.total / M_PER_INCH),
        "heading_error_deg": summary_stats(e.heading),
        "rotation_error_deg": summary_stats(e.rotation),
        "per_photo": _per_photo(pairs.names, e),
    }


def _per_photo(names: list[str], e: _Errors) -> list[dict]:
    """accuracy.json's ``per_photo`` records."""
    return [
        {
            "name": n,
            "position_error_m": float(a),
            "line_of_sight_m": float(b),
            "transverse_m": float(c),
            "heading_error_deg": float(d),
        }
        for n, a, b, c, d in zip(names, e.total, e.los, e.transverse, e.heading, strict=True)
    ]
