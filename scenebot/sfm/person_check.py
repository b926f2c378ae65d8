"""Is a person's map bent? Two checks that need no truth (``report.json`` ``person_check``).

A person's map has nothing like the robot's odometry, compass or turn-in-place circles to
hold it: a stretch of photos of a white wall, registered from 20-60 points each, can fold
the map there (the office walk of 32 photos at 320 x 240: a run of photos 0.3-2.7 m off, or
the far side of the room turned by the fold) while every photo's reprojection error stays
small. Two things still contradict such a map:

1. **Verified pairs the map does not hold** (:func:`pair_track_shares`). Two photos whose
   features matched with a verified two-view geometry (at least :data:`MIN_PAIR_INLIERS`
   inlier matches, enough to register one photo from the other, and a baseline that can
   triangulate them: :data:`MIN_PAIR_ANGLE_DEG`) see the same surface; in a
   right map most of those matches are one 3D point each (the same track), as much as for
   the map's other pairs. Across a fold the map places the two views so that their matches
   do not meet: the share of the pair's inliers that are one track falls to a few percent
   (office walks: 0-16 % at the folds, 30-98 % for every pair of maps within a few cm).
   A pair whose share is below ``sfm.person_min_pair_share`` times the median pair's
   contradicts the map.
2. **The eye-height plane** (:func:`height_plane`). The round-0 photos of a guided campaign
   are a walk around the room, the person standing: their camera centres lie within a few
   centimetres of one horizontal plane (``sfm.person_height_std_m``). A robust plane fit
   (least median of squares, then Tukey-biweight refinement) of their centres in the
   person's frame (m) names the photos farther than ``PLANE_OUTLIER_SIGMAS`` standard
   deviations from it, and says the walk is not planar when the fit's own robust spread
   exceeds ``PLANE_SPREAD_FACTOR`` times the expected one (a map bent about a horizontal
   axis). Its normal is also the walk's up, which the frame's up should match.

Photos named by either check are the ones the stage maps again or leaves out
(:mod:`scenebot.sfm.stage`); the truth is never read here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pycolmap

from scenebot.sfm.features import open_database

MIN_PAIR_INLIERS = 30
"""A verified pair counts for the pair check from this many inlier matches (COLMAP's
mapper registers a photo from 30 inlier correspondences: ``abs_pose_min_num_inliers``)."""
MIN_PAIR_ANGLE_DEG = 4.0
"""A verified pair counts for the pair check only when its baseline subtends at least this
angle at the median depth of either photo's points: two photos turned in place (a robot's
circle: 2-5 cm apart at 1.5-3 m, 0.5-2 deg) triangulate their matches with a depth error of
(1 px / focal) / angle, 10-20 % at 320 x 240, and such a track splits where a third photo
sees the point, so their share says little (a right circle of the robot's folder: 19-22 %
against a median of 89 %). Most of the walk's pairs count (neighbours 0.3-0.6 m apart at
4-5 m: 3.5-9 deg); each of five bent office walks kept 1-9 contradicted pairs."""
PLANE_OUTLIER_SIGMAS = 4.0
"""A standing photo farther than this many expected standard deviations from the plane of
the others is off where the person held the camera."""
PLANE_SPREAD_FACTOR = 2.0
"""The standing photos as a whole are not on one plane when their robust spread about it
exceeds this many times the expected one."""
LMEDS_SAMPLES = 300
"""Random triples of camera centres tried for the plane's least-median start."""
TUKEY_C = 4.685
"""Tukey biweight constant (95 % efficiency under Gaussian residuals)."""


@dataclass
class PersonCheck:
    """The checks' verdict on one map.

    Attributes:
        ok: neither check found a problem.
        problems: one message per problem, naming the photos and the setting.
        contradicted: pairs ``(name_a, name_b, inliers, share)`` the map does not hold.
        off_plane: standing photo -> distance (m) from the plane of the others.
        pairs_per_photo: photo -> verified pairs of it the pair check counted.
        stats: ``pairs`` (counts, median share, threshold) and ``plane`` (normal, tilt
            against the frame's z (deg), robust spread (m), expected, photos); report.json.
    """

    ok: bool
    problems: list[str] = field(default_factory=list)
    contradicted: list[tuple[str, str, int, float]] = field(default_factory=list)
    off_plane: dict[str, float] = field(default_factory=dict)
    stats: dict = field(default_factory=dict)
    pairs_per_photo: dict[str, int] = field(default_factory=dict)

    @property
    def named_photos(self) -> set[str]:
        """Every photo a problem names (off the plane, or in a contradicted pair)."""
        return set(self.off_plane) | {n for a, b, *_ in self.contradicted for n in (a, b)}

    @property
    def badness(self) -> tuple[int, int]:
        """Sort key among maps of the same photos: contradicted pairs, then photos off the
        plane (fewer is better)."""
        return len(self.contradicted), len(self.off_plane)

    def as_dict(self) -> dict:
        return {
            "ok": self.ok,
            "problems": self.problems,
            "contradicted_pairs": [
                {"image_a": a, "image_b": b, "inliers": n, "track_share": s}
                for a, b, n, s in self.contradicted
            ],
            "off_plane_m": self.off_plane,
            **self.stats,
        }


def pair_track_shares(
    rec: pycolmap.Reconstruction,
    db_path,
    min_inliers: int = MIN_PAIR_INLIERS,
    min_angle_deg: float = MIN_PAIR_ANGLE_DEG,
) -> list[tuple[str, str, int, float]]:
    """Per verified pair of registered photos with at least ``min_inliers`` inlier matches
    and a baseline that can triangulate them (``min_angle_deg`` at the median depth of the 3D
    points of either photo, the nearer): the share of those matches whose two features are
    observations of one 3D point.

    Returns:
        ``(name_a, name_b, inliers, share)`` per pair, names in the database's pair order.
    """
    by_name = {rec.image(i).name: i for i in rec.reg_image_ids()}
    tracks: dict[int, np.ndarray] = {}
    depths: dict[int, float] = {}

    def median_depth(image_id: int) -> float:
        if image_id not in depths:
            im = rec.image(image_id)
            ids = [p.point3D_id for p in im.points2D if p.has_point3D()]
            X = np.array([rec.point3D(i).xyz for i in ids]).reshape(-1, 3)
            z = (im.cam_from_world() * X)[:, 2] if len(X) else np.zeros(0)
            depths[image_id] = float(np.median(z)) if len(z) else math.inf
        return depths[image_id]

    def can_triangulate(ia: int, ib: int) -> bool:
        a, b = rec.image(ia), rec.image(ib)
        baseline = float(np.linalg.norm(a.projection_center() - b.projection_center()))
        depth = min(median_depth(ia), median_depth(ib))  # a photo registered off: no points
        return baseline >= math.tan(math.radians(min_angle_deg)) * depth

    def point_ids(image_id: int) -> np.ndarray:
        """The 3D point of each feature of the photo (-1: none)."""
        if image_id not in tracks:
            im = rec.image(image_id)
            tracks[image_id] = np.array(
                [p.point3D_id if p.has_point3D() else -1 for p in im.points2D], np.int64
            )
        return tracks[image_id]

    out = []
    with open_database(db_path) as db:
        names = {im.image_id: im.name for im in db.read_all_images()}
        pair_ids, inliers = db.read_two_view_geometry_num_inliers()
        for pid, n in zip(pair_ids, inliers, strict=True):
            if n < min_inliers:
                continue
            a, b = pycolmap.pair_id_to_image_pair(pid)
            na, nb = names.get(a), names.get(b)
            if na not in by_name or nb not in by_name:
                continue
            if not can_triangulate(by_name[na], by_name[nb]):
                continue
            m = db.read_two_view_geometry(a, b).inlier_matches
            pa, pb = point_ids(by_name[na])[m[:, 0]], point_ids(by_name[nb])[m[:, 1]]
            same = int(np.sum((pa >= 0) & (pa == pb)))
            out.append((na, nb, int(n), same / max(len(m), 1)))
    return out


def contradicted_pairs(
    shares: list[tuple[str, str, int, float]], min_share: float
) -> tuple[list[tuple[str, str, int, float]], dict]:
    """The pairs whose track share is below ``min_share`` times the median pair's.

    Returns:
        The contradicted pairs and stats (pairs checked, median share, threshold).
    """
    if not shares:
        return [], {"checked": 0}
    median = float(np.median([s for *_, s in shares]))
    threshold = min_share * median
    bad = [r for r in shares if r[3] < threshold]
    return bad, {"checked": len(shares), "median_share": median, "threshold": threshold}


def fit_plane(C: np.ndarray, seed: int = 0, iterations: int = 10) -> tuple[np.ndarray, float]:
    """Robust plane through points: least median of squares over random triples, then
    Tukey-biweight refinement (scale: the residuals' MAD).

    Args:
        C: (N, 3) points, N >= 3, not all on one line.

    Returns:
        The unit normal (3,) (sign: +z) and the offset ``d`` of the plane ``n @ x = d``.
    """
    C = np.asarray(C, float)
    rng = np.random.default_rng(seed)
    best: tuple[float, np.ndarray, float] | None = None
    for _ in range(LMEDS_SAMPLES if len(C) > 3 else 1):
        i = rng.choice(len(C), 3, replace=False) if len(C) > 3 else np.arange(3)
        n = np.cross(C[i[1]] - C[i[0]], C[i[2]] - C[i[0]])
        norm = float(np.linalg.norm(n))
        if norm < 1e-12:
            continue
        n = n / norm
        med = float(np.median(np.abs((C - C[i[0]]) @ n)))
        if best is None or med < best[0]:
            best = (med, n, float(C[i[0]] @ n))
    if best is None:
        raise ValueError("the camera centres lie on one line: no plane")
    _, n, d = best
    for _ in range(iterations):
        r = C @ n - d
        scale = 1.4826 * float(np.median(np.abs(r))) + 1e-12
        w = np.clip(1.0 - (r / (TUKEY_C * scale)) ** 2, 0.0, None) ** 2
        if w.sum() <= 0:
            break
        mu = (w[:, None] * C).sum(0) / w.sum()
        X = (C - mu) * np.sqrt(w)[:, None]
        n = np.linalg.eigh(X.T @ X)[1][:, 0]
        d = float(mu @ n)
    if n[2] < 0:
        n, d = -n, -d
    return n, d


def height_plane(
    names: list[str], C: np.ndarray, expected_std_m: float
) -> tuple[dict[str, float], dict]:
    """The eye-height plane of standing photos (module docstring, check 2).

    Args:
        names: (N,) the standing photos; C: (N, 3) their camera centres, person frame (m,
            z up).
        expected_std_m: the expected spread (m) of their heights about one plane.

    Returns:
        Photo -> distance (m) from the plane for the photos beyond
        ``PLANE_OUTLIER_SIGMAS * expected_std_m``, and stats: ``photos``, ``normal``,
        ``tilt_deg`` (the normal against the frame's z), ``robust_std_m`` (MAD of the
        residuals), ``expected_std_m``, ``planar`` (robust spread within
        ``PLANE_SPREAD_FACTOR`` times expected).
    """
    n, d = fit_plane(C)
    r = C @ n - d
    robust = 1.4826 * float(np.median(np.abs(r)))
    limit = PLANE_OUTLIER_SIGMAS * expected_std_m
    off = {nm: float(x) for nm, x in zip(names, r, strict=True) if abs(x) > limit}
    stats = {
        "photos": len(names),
        "normal": [float(v) for v in n],
        "tilt_deg": math.degrees(math.acos(min(1.0, abs(float(n[2]))))),
        "robust_std_m": robust,
        "rms_m": float(np.sqrt(np.mean(r**2))),
        "expected_std_m": expected_std_m,
        "outlier_limit_m": limit,
        "planar": robust <= PLANE_SPREAD_FACTOR * expected_std_m,
    }
    return off, stats


def check_person_map(
    rec: pycolmap.Reconstruction,
    db_path,
    *,
    standing: list[str],
    to_frame: tuple[float, np.ndarray, np.ndarray] | None,
    min_pair_share: float,
    height_std_m: float,
) -> PersonCheck:
    """Both checks on a person's map (module docstring).

    Args:
        rec: the model (any frame).
        db_path: the scene database (verified pairs).
        standing: the photos taken standing at eye height (a guided campaign's round 0).
        to_frame: ``(scale, R, t)`` from the model to the person's metric frame (z up), or
            None when the map has no metric scale (the plane check is then skipped).
        min_pair_share: ``sfm.person_min_pair_share``.
        height_std_m: ``sfm.person_height_std_m`` (0: no plane check).

    Returns:
        The verdict, with a message per problem naming the photos and the setting.
    """
    problems: list[str] = []
    shares = pair_track_shares(rec, db_path)
    bad, pair_stats = contradicted_pairs(shares, min_pair_share)
    if bad:
        listing = ", ".join(f"{_short(a)}-{_short(b)} ({s:.0%} of {n})" for a, b, n, s in bad[:8])
        problems.append(
            f"{len(bad)} verified pair(s) of photos the map does not hold (their matches are "
            f"not one 3D point: the map is folded or a photo registered off): {listing}; the "
            f"median pair holds {pair_stats['median_share']:.0%} (sfm.person_min_pair_share "
            f"= {min_pair_share})"
        )
    off: dict[str, float] = {}
    plane_stats: dict = {"checked": False}
    by_name = {rec.image(i).name: i for i in rec.reg_image_ids()}
    names = [n for n in standing if n in by_name]
    if height_std_m > 0 and to_frame is not None and len(names) >= 6:
        s, R, t = to_frame
        C = np.array([rec.image(by_name[n]).projection_center() for n in names])
        C = s * C @ np.asarray(R).T + np.asarray(t)
        off, plane_stats = height_plane(names, C, height_std_m)
        plane_stats["checked"] = True
        if off:
            listing = ", ".join(f"{_short(n)} ({r:+.2f} m)" for n, r in list(off.items())[:8])
            problems.append(
                f"{len(off)} standing photo(s) registered off the eye-height plane of the "
                f"others by more than {plane_stats['outlier_limit_m']:.2f} m (4 x "
                f"sfm.person_height_std_m = {height_std_m} m): {listing}"
            )
        if not plane_stats["planar"]:
            problems.append(
                f"the standing photos' camera centres spread {plane_stats['robust_std_m']:.2f} m "
                f"about one plane, more than {PLANE_SPREAD_FACTOR:g} x sfm.person_height_std_m "
                f"= {height_std_m} m: the map is bent"
            )
    elif height_std_m > 0:
        plane_stats["why_not"] = (
            "no metric scale" if to_frame is None else f"{len(names)} standing photos (< 6)"
        )
    stats = {"pairs": pair_stats, "plane": plane_stats}
    per_photo: dict[str, int] = {}
    for a, b, *_ in shares:
        for n in (a, b):
            per_photo[n] = per_photo.get(n, 0) + 1
    return PersonCheck(not problems, problems, bad, off, stats, per_photo)


def _short(name: str) -> str:
    """A photo's file name without its folders (``r000_0020.jpg``)."""
    return name.rsplit("/", 1)[-1]
