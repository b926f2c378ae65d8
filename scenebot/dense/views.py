"""Source-view selection and depth ranges from a sparse COLMAP model.

A good source view for a reference view shares many sparse points with it and sees them under
a useful triangulation angle: too small and depth is ill-conditioned, too large and the
appearance changes. Depth ranges come from the depths of the view's own sparse points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pycolmap


@dataclass
class ViewPlan:
    """What the depth estimator needs for one reference view.

    Attributes:
        image_id: COLMAP image id of the reference view.
        name: image name.
        sources: source image ids, best first.
        shared_points: number of sparse points shared with each source.
        median_angle_deg: median triangulation angle of the shared points, per source.
        depth_range: (min, max) z-depth to search, model units (metres).
    """

    image_id: int
    name: str
    sources: list[int]
    shared_points: list[int]
    median_angle_deg: list[float]
    depth_range: tuple[float, float]


def _angle_weight(angle_deg: float, min_deg: float, full_deg: float = 5.0) -> float:
    """Preference for triangulation angles: rises as the square of the angle to 1 at
    ``full_deg`` (depth precision grows with the baseline, and a pose error of a millimetre
    is a large share of a short one), falls beyond 30 deg (appearance changes)."""
    if angle_deg < min_deg:
        return 0.0
    w = min(angle_deg / full_deg, 1.0) ** 2
    if angle_deg > 30.0:
        w *= 30.0 / angle_deg
    return w


def select_views(
    rec: pycolmap.Reconstruction,
    num_sources: int = 4,
    min_shared_points: int = 10,
    min_angle_deg: float = 1.0,
    depth_margin: float = 0.25,
    image_ids: list[int] | None = None,
    full_angle_deg: float = 5.0,
) -> tuple[list[ViewPlan], list[str]]:
    """Choose source views and depth ranges for every registered image.

    Args:
        rec: sparse reconstruction (registered images with 3D point observations).
        num_sources: maximum sources per reference view.
        min_shared_points: minimum shared sparse points for a source.
        min_angle_deg: minimum median triangulation angle for a source, degrees.
        full_angle_deg: a source's shared points count fully from this median angle on
            (degrees); below it they are weighted by the square of the angle's share.
        depth_margin: the range [p1, p99] of sparse depths is widened to
            [p1 * (1 - margin), p99 * (1 + margin)].
        image_ids: reference views to plan (default: all registered images).

    Returns:
        (plans, isolated): one plan per reference view that has at least one source, and the
        names of the views without any source (no overlap).

    Raises:
        ValueError: fewer than 2 registered images.
    """
    reg = sorted(rec.reg_image_ids())
    if len(reg) < 2:
        raise ValueError(
            f"the sparse model has {len(reg)} registered image(s); dense stereo needs at least 2 "
            "registered views with overlapping content (run more capture rounds or check SfM)"
        )
    centers = {i: rec.image(i).projection_center() for i in reg}
    # observations: image id -> array of point ids
    obs: dict[int, np.ndarray] = {}
    for i in reg:
        img = rec.image(i)
        obs[i] = np.array([p.point3D_id for p in img.points2D if p.has_point3D()], dtype=np.int64)
    pid_to_imgs: dict[int, set[int]] = {}
    for i, pids in obs.items():
        for p in pids.tolist():
            pid_to_imgs.setdefault(p, set()).add(i)
    xyz = {p: rec.point3D(p).xyz for p in pid_to_imgs}

    plans: list[ViewPlan] = []
    isolated: list[str] = []
    for i in image_ids if image_ids is not None else reg:
        img = rec.image(i)
        pids = obs[i]
        shared: dict[int, list[int]] = {}
        for p in pids.tolist():
            for j in pid_to_imgs[p]:
                if j != i:
                    shared.setdefault(j, []).append(p)
        scored = []
        for j, plist in shared.items():
            if len(plist) < min_shared_points:
                continue
            P = np.array([xyz[p] for p in plist])
            a = P - centers[i]
            b = P - centers[j]
            cosang = np.sum(a * b, 1) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
            ang = float(np.degrees(np.median(np.arccos(np.clip(cosang, -1, 1)))))
            w = _angle_weight(ang, min_angle_deg, full_angle_deg)
            if w > 0:
                scored.append((len(plist) * w, j, len(plist), ang))
        if not scored or len(pids) == 0:
            isolated.append(img.name)
            continue
        scored.sort(reverse=True)
        scored = scored[:num_sources]
        P = np.array([xyz[p] for p in pids.tolist()])
        cam = img.cam_from_world()
        z = (P @ cam.rotation.matrix().T + cam.translation)[:, 2]
        z = z[z > 0]
        if len(z) == 0:
            isolated.append(img.name)
            continue
        lo, hi = np.percentile(z, [1, 99])
        plans.append(
            ViewPlan(
                image_id=i,
                name=img.name,
                sources=[s[1] for s in scored],
                shared_points=[s[2] for s in scored],
                median_angle_deg=[s[3] for s in scored],
                depth_range=(float(lo * (1 - depth_margin)), float(hi * (1 + depth_margin))),
            )
        )
    return plans, isolated
