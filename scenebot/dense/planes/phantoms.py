"""Step 1 of the plane fill, continued: planes that the measured depth of the views
contradicts are dropped (``drop_phantoms``).

Those seen through (more measured depth behind their extent than on it), those that lie
behind another plane (a slice beneath the floor from a repeating carpet)
(:func:`plane_evidence`, :func:`validate_planes`), and shadows: of two parallel planes a
few centimetres apart (``shadow_gap_m``), the one fewer views support (a circle of photos
registered 0.2 degrees off puts its wall a few cm in front of itself; :func:`shadow_planes`).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from scenebot.dense.planes.geometry import MeasuredRays, Plane, crossed_before


def plane_evidence(
    depth: np.ndarray,
    K: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    planes: list[Plane],
    *,
    distance_m: float,
    rel_distance: float,
    stride: int = 4,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What one view's measured depth (every ``stride``-th pixel) says about the planes.

    A measured point lies on a plane within the larger of ``distance_m`` and
    ``rel_distance`` of its depth.

    Returns:
        ``on`` (P,): measured points on each plane; ``behind`` (P,): measured points behind
        each plane's extent along their ray (a phantom plane floating in the room is seen
        through); ``hidden`` (P, P): points on plane j behind plane k's extent (a phantom
        plane beneath the floor lies behind the floor).
    """
    rays = MeasuredRays.of_view(depth, K, R, t, stride)
    n = len(planes)
    X = rays.points
    tol = rays.on_plane_tolerance(distance_m, rel_distance)
    on = np.zeros((n, len(rays.z)), bool)
    back = np.zeros((n, len(rays.z)), bool)
    for j, pl in enumerate(planes):
        on[j] = np.abs(X @ pl.normal + pl.offset) < tol
        z, cand = crossed_before(pl, rays, distance_m, rel_distance)
        if cand.any():
            cand[cand] = pl.inside(rays.centre + z[cand, None] * rays.ray[cand])
        back[j] = cand
    hidden = on.astype(np.int64) @ back.T.astype(np.int64)
    np.fill_diagonal(hidden, 0)
    return on.sum(1), back.sum(1), hidden


def validate_planes(
    planes: list[Plane], on: np.ndarray, behind: np.ndarray, hidden: np.ndarray,
    max_seen_through: float, max_hidden: float, not_hidden: Iterable[int] = (),
) -> tuple[list[int], dict[int, str]]:  # fmt: skip
    """Planes kept (indices) and why the others were dropped: first those seen through
    (``behind > max_seen_through * on``), then, among the rest, those whose points mostly
    lie behind another kept plane (``hidden > max_hidden * on``), except ``not_hidden``
    (the ceiling: its few points lie at the walls' top edges, where a wall's extent closed
    over a gap hides them)."""
    why: dict[int, str] = {}
    for j in range(len(planes)):
        if behind[j] > max_seen_through * max(on[j], 1):
            why[j] = f"seen through: {behind[j]} measured points behind it, {on[j]} on it"
    kept = [j for j in range(len(planes)) if j not in why]
    for j in list(kept):
        if j in set(not_hidden):
            continue
        others = [k for k in kept if k != j]
        worst = max((hidden[j, k] for k in others), default=0)
        if worst > max_hidden * max(on[j], 1):
            why[j] = f"hidden: {worst} of its {on[j]} points lie behind another plane"
    return [j for j in kept if j not in why], why


def shadow_planes(
    planes: list[Plane], support: np.ndarray, max_gap_m: float, *, max_angle_deg: float,
    min_overlap: float = 0.3,
) -> dict[int, str]:  # fmt: skip
    """Planes that shadow a plane seen by more views, a few centimetres beside it.

    A handful of views whose poses are slightly off (a turn-in-place circle registered with a
    0.2 degree error between its photos) put the wall they see a few centimetres in front of
    where every other view puts it, and RANSAC finds that shadow as a plane of its own,
    parallel to the wall and as large in points. The wall is the one more views support
    (of two that as many views support, the one with more points).

    Args:
        planes: the planes, with their extents.
        support: (P,) number of views whose measured depth lies on each plane.
        max_gap_m: parallel planes closer than this are one surface seen twice.
        max_angle_deg: planes within this angle are parallel.
        min_overlap: share of the weaker plane's cells inside the stronger one's extent.

    Returns:
        {index: reason} of the shadow planes.
    """
    why: dict[int, str] = {}
    cos_par = np.cos(np.radians(max_angle_deg))
    order = sorted(range(len(planes)), key=lambda j: (-support[j], -planes[j].inliers))
    for a, i in enumerate(order):
        if i in why:
            continue
        pi = planes[i]
        for j in order[a + 1 :]:
            pj = planes[j]
            weaker = support[j] < support[i] or (
                support[j] == support[i] and pj.inliers < pi.inliers
            )  # as many views on both: the one with more points is the surface
            if j in why or not weaker or abs(pi.normal @ pj.normal) < cos_par:
                continue
            gap = abs(pj.origin @ pi.normal + pi.offset)
            if gap > max_gap_m:
                continue
            _, X = pj.cell_centres()
            overlap = float(pi.inside(X).mean()) if len(X) else 0.0
            if overlap >= min_overlap:
                why[j] = (f"shadow of a plane {100 * gap:.1f} cm away ({100 * overlap:.0f}% "
                          f"overlap), seen by {support[j]} views against {support[i]}")  # fmt: skip
    return why
