"""Pairs of photos their cameras' own orientation contradicts: left out of mapping.

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
from scenebot.sfm.photos import Photo


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


def drop_pairs_against_orientation(
    db_path: Path, photos: list[Photo], max_deg: float, min_num_matches: int
) -> dict:
    """Delete the two-view geometry of every verified pair (``min_num_matches`` inliers or
    more) of two photos with an ``orientation`` whose relative rotation from its matches
    differs from the orientations' by more than ``max_deg``, but for those needed to keep
    the photos joined (:func:`contradicted`); the matches stay (the pair is not matched
    again). A pair whose relative pose cannot be estimated stays.

    Returns:
        report.json's ``orientation_pairs``: ``max_deg``, ``photos`` (with an orientation),
        ``checked``, ``dropped``, ``kept_to_connect`` (beyond ``max_deg`` but needed to keep
        the photos joined), ``no_pose``, ``disagreement_deg`` (median and p90 over the
        checked pairs), ``seconds``.
    """
    t0 = time.perf_counter()
    prior = {p.name: rotation_from_orientation(p.orientation) for p in photos if p.orientation}
    stats: dict = {"max_deg": max_deg, "photos": len(prior), "checked": 0, "dropped": 0,
                   "no_pose": 0}  # fmt: skip
    if max_deg <= 0 or len(prior) < 2:
        return stats | {"seconds": time.perf_counter() - t0}
    judged: list[tuple[float, int, int]] = []  # (disagreement, image id a, image id b)
    with open_database(db_path) as db:
        images = {im.image_id: im for im in db.read_all_images() if im.name in prior}
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
            tv = db.read_two_view_geometry(a, b)
            ca, cb = cameras[images[a].camera_id], cameras[images[b].camera_id]
            ok = pycolmap.estimate_two_view_geometry_pose(ca, kp(a), cb, kp(b), tv)
            if not ok or tv.cam2_from_cam1 is None:
                stats["no_pose"] += 1
                continue
            stats["checked"] += 1
            expected = prior[images[b].name] @ prior[images[a].name].T
            judged.append(
                (rotation_angle_deg(tv.cam2_from_cam1.rotation.matrix() @ expected.T), a, b)
            )
        for a, b in contradicted(judged, max_deg):
            db.delete_two_view_geometry(a, b)
            stats["dropped"] += 1
    stats["kept_to_connect"] = sum(j[0] > max_deg for j in judged) - stats["dropped"]
    angles = [j[0] for j in judged]
    if angles:
        stats["disagreement_deg"] = {
            "median": float(np.median(angles)),
            "p90": float(np.percentile(angles, 90)),
        }
    return stats | {"seconds": time.perf_counter() - t0}
