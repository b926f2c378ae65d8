"""Pairs of photos their cameras' own sensors contradict: left out of mapping.

Two sensors: the orientation (below) and the tracked motion (a phone's visual-inertial
odometry, :class:`~scenebot.sfm.photos.Motion`), whose relative pose of two photos of one
session gives the pair's translation direction too: a wallpaper matched one motif along the
same wall gives the right rotation and a translation pointing elsewhere. Judged with the
simulator's truth (tracking drifting 1% of the distance walked, the check allowing 3%): the
flat's 178-photo walk, 397 of its 629 wrong pairs dropped and none of its 1,738 right ones;
the office's 200-photo walk, 2,526 of 3,739 and none right.

A phone records its orientation with each photo: the compass heading (good to 5-15 degrees
indoors) and, from the accelerometer, the pitch and roll (good to a degree). Two photos'
readings give their relative rotation; the verified matches of the pair give it too (the
relative pose of its two-view geometry). On a repeated texture they disagree: a wallpaper
motif matched to its copy on another wall makes a pair whose matches say the cameras faced
the same way while they faced walls 90 or 180 degrees apart.

Measured on the flat's person walk (80 photos, 2026-11-28, a campaign at d671de9, judged
with the simulator's truth): 1,316 of its 2,274 verified pairs were wrong (under half their
matches consistent with the true poses), and the incremental mapper placed 28 of 68
registered photos 1-4.3 m off. The wrong pairs' rotation missed the true one by 90 degrees
at the median (99 of them within 10 degrees); they support each other in triangles as much
as the right pairs do (a wall of copies agrees with itself), so loop consistency of the
pairs' rotations cannot tell them apart, and the walk's order cannot either (photos 4-7 join
only by wrong pairs). Readings simulated from the truth with a 10-degree compass and a
1-degree accelerometer: 1,140 of the wrong pairs and 71 of the 958 right ones beyond 35
degrees; with a 5-degree compass at 25 degrees, 1,158 and 66, and the walk mapped then
registered 80 of 80, none off (median 0.1 cm after a similarity fit).
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pycolmap

from scenebot.geometry import orientation_rotation, rotation_angle_deg
from scenebot.sfm.features import open_database
from scenebot.sfm.photos import Motion, Photo

MOTION_JITTER_M = 0.02
"""Error (m) of a tracked camera position however little the camera moved since the other
photo of a pair (the tracking's noise): a pair closer than three times this is not judged by
its direction."""


def rotation_from_orientation(orientation: tuple[float, float, float]) -> np.ndarray:
    """cam_from_world rotation (the compass frame) of a photo's ``(heading, pitch, roll)``
    (deg)."""
    h, p, r = (math.radians(v) for v in orientation)
    return orientation_rotation(h, p, r)


def contradicted(judged: list[tuple[float, int, int]], max_deg: float) -> list[tuple[int, int]]:
    """The pairs to drop among ``judged`` ((disagreement deg, photo a, photo b)): those
    beyond ``max_deg``, but for the ones a spanning forest of the pairs, taken in order of
    agreement, needs to keep every photo joined to what it was joined to (Kruskal's rule). A
    pair's relative pose can be wrong while its matches are right (a short baseline, a few
    dozen matches: the office's 32-photo walk at 320 x 240 had right pairs 14-100 degrees
    off, and dropping them split the walk in two); the map's own check judges a pair kept that
    way, as it judges every pair."""
    parent: dict[int, int] = {}

    def root(i: int) -> int:
        parent.setdefault(i, i)
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    out = []
    for angle, a, b in sorted(judged):
        ra, rb = root(a), root(b)
        if ra != rb:
            parent[ra] = rb  # joins two parts: kept, whatever its angle
        elif angle > max_deg:
            out.append((a, b))
    return out


def motion_direction_bound(a: Motion, b: Motion, max_deg: float, drift: float) -> float | None:
    """The bound (deg) on the angle between a pair's relative translation from its matches
    and the one the cameras' tracked motion gives: ``max_deg`` plus the angle the tracking's
    error can turn the tracked baseline by (three standard deviations: ``drift`` per metre
    walked between the two photos, at least :data:`MOTION_JITTER_M`); None when the two
    photos are of different sessions or too close for the direction to say anything (the
    bound would reach 90 deg)."""
    if a.session != b.session:
        return None
    sigma = max(MOTION_JITTER_M, drift * abs(b.walked_m - a.walked_m))
    baseline = float(np.linalg.norm(a.center - b.center))
    bound = max_deg + math.degrees(math.atan2(3.0 * sigma, baseline))
    return bound if bound < 90.0 else None


def translation_angle_deg(t_est: np.ndarray, a: Motion, b: Motion) -> float:
    """Angle (deg) between a pair's cam2_from_cam1 translation ``t_est`` (from its matches;
    its scale unknown) and the one the tracked poses of photos ``a`` (1) and ``b`` (2) give."""
    t = b.rotation @ (a.center - b.center)
    n = float(np.linalg.norm(t_est) * np.linalg.norm(t))
    if n == 0.0:
        return 0.0
    return math.degrees(math.acos(float(np.clip(np.dot(t_est, t) / n, -1.0, 1.0))))


def drop_pairs_against_orientation(
    db_path: Path,
    photos: list[Photo],
    max_deg: float,
    min_num_matches: int,
    motion_max_deg: float = 0.0,
    motion_drift: float = 0.0,
) -> dict:
    """Delete the two-view geometry of every verified pair (``min_num_matches`` inliers or
    more) its cameras' own sensors contradict, but for those needed to keep the photos joined
    (:func:`contradicted`); the matches stay (the pair is not matched again). A pair whose
    relative pose cannot be estimated stays. Two checks, each off at 0:

    - orientation (``max_deg``): two photos with an ``orientation`` whose relative rotation
      from the matches differs from the orientations' by more than ``max_deg``;
    - motion (``motion_max_deg``): two photos of one motion-tracking session whose relative
      translation from the matches points elsewhere than the tracked one by more than
      ``motion_max_deg`` plus what the tracking's drift (``motion_drift`` per metre walked
      between them) allows (:func:`motion_direction_bound`), or whose relative rotation
      differs from the tracked one by more than ``motion_max_deg``. A wallpaper matched one
      motif along the same wall gives the right rotation and a wrong translation: what
      the orientation cannot see.

    The forest orders the pairs by their worst disagreement as a share of its bound.

    Returns:
        report.json's ``orientation_pairs``: ``max_deg``, ``photos`` (with an orientation),
        ``checked``, ``dropped``, ``kept_to_connect`` (beyond a bound but needed to keep
        the photos joined), ``no_pose``, ``disagreement_deg`` (median and p90 over the
        checked pairs), ``motion`` (``max_deg``, ``drift``, ``photos`` with a tracked pose,
        ``checked`` pairs, ``dropped`` by it, ``angle_deg`` median and p90 of the
        translation's disagreement), ``seconds``.
    """
    t0 = time.perf_counter()
    prior = {p.name: rotation_from_orientation(p.orientation) for p in photos if p.orientation}
    if max_deg <= 0:
        prior = {}
    tracked = {p.name: p.motion for p in photos if p.motion is not None}
    if motion_max_deg <= 0:
        tracked = {}
    stats: dict = {"max_deg": max_deg, "photos": len(prior), "checked": 0, "dropped": 0,
                   "no_pose": 0}  # fmt: skip
    mstats: dict = {"max_deg": motion_max_deg, "drift": motion_drift, "photos": len(tracked),
                    "checked": 0, "dropped": 0}  # fmt: skip
    if len(prior) < 2 and len(tracked) < 2:
        return stats | {"motion": mstats, "seconds": time.perf_counter() - t0}
    # (worst disagreement / its bound, image id a, image id b, orientation's angle or None,
    #  motion's translation angle or None, the reason it is beyond: "orientation"/"motion")
    judged: list[tuple[float, int, int, float | None, float | None, str]] = []
    with open_database(db_path) as db:
        images = {im.image_id: im for im in db.read_all_images()
                  if im.name in prior or im.name in tracked}  # fmt: skip
        cameras = {c.camera_id: c for c in db.read_all_cameras()}
        keypoints: dict[int, np.ndarray] = {}

        def kp(iid: int) -> np.ndarray:
            if iid not in keypoints:
                keypoints[iid] = np.asarray(db.read_keypoints(iid))[:, :2].astype(np.float64)
            return keypoints[iid]

        pair_ids, inliers = db.read_two_view_geometry_num_inliers()
        for pid, n in zip(pair_ids, inliers, strict=True):
            a, b = pycolmap.pair_id_to_image_pair(int(pid))
            if a not in images or b not in images or n < min_num_matches:
                continue
            na, nb = images[a].name, images[b].name
            use_prior = na in prior and nb in prior
            ma, mb = tracked.get(na), tracked.get(nb)
            bound_t = (
                motion_direction_bound(ma, mb, motion_max_deg, motion_drift)
                if ma is not None and mb is not None
                else None
            )
            same_session = ma is not None and mb is not None and ma.session == mb.session
            if not use_prior and not same_session:
                continue
            tv = db.read_two_view_geometry(a, b)
            ca, cb = cameras[images[a].camera_id], cameras[images[b].camera_id]
            ok = pycolmap.estimate_two_view_geometry_pose(ca, kp(a), cb, kp(b), tv)
            if not ok or tv.cam2_from_cam1 is None:
                stats["no_pose"] += 1
                continue
            R_est = tv.cam2_from_cam1.rotation.matrix()
            shares, rot, tdir = [(0.0, "")], None, None
            if use_prior:
                stats["checked"] += 1
                expected = prior[nb] @ prior[na].T
                rot = rotation_angle_deg(R_est @ expected.T)
                shares.append((rot / max_deg, "orientation"))
            if same_session:
                mstats["checked"] += 1
                mrot = rotation_angle_deg(R_est @ (mb.rotation @ ma.rotation.T).T)
                shares.append((mrot / motion_max_deg, "motion"))
                if bound_t is not None:
                    t_est = np.asarray(tv.cam2_from_cam1.translation, float).ravel()
                    tdir = translation_angle_deg(t_est, ma, mb)
                    shares.append((tdir / bound_t, "motion"))
            share, why = max(shares)
            judged.append((share, a, b, rot, tdir, why))
        reasons = {(j[1], j[2]): j[5] for j in judged}
        for a, b in contradicted([(j[0], j[1], j[2]) for j in judged], 1.0):
            db.delete_two_view_geometry(a, b)
            (stats if reasons[(a, b)] == "orientation" else mstats)["dropped"] += 1
    stats["kept_to_connect"] = (
        sum(j[0] > 1.0 for j in judged) - stats["dropped"] - mstats["dropped"]
    )
    angles = [j[3] for j in judged if j[3] is not None]
    if angles:
        stats["disagreement_deg"] = {
            "median": float(np.median(angles)),
            "p90": float(np.percentile(angles, 90)),
        }
    tangles = [j[4] for j in judged if j[4] is not None]
    if tangles:
        mstats["angle_deg"] = {
            "median": float(np.median(tangles)),
            "p90": float(np.percentile(tangles, 90)),
        }
    return stats | {"motion": mstats, "seconds": time.perf_counter() - t0}
