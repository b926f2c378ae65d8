"""Step 1 of the plane fill, continued: planes that the measured depth of the views
contradicts are dropped (``drop_phantoms``).

Those seen through (more measured depth behind their extent than on it), those that lie
behind another plane (a slice beneath the floor from a repeating carpet)
(:func:`plane_evidence`, :func:`validate_planes`), and shadows: of two parallel planes a
few centimetres apart (``shadow_gap_m``), the one fewer views prefer, each view voting for
the plane that holds more of its measured points (a circle of photos registered 0.2 degrees
off puts its wall a few cm in front of itself; :func:`shadow_planes`).
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
    min_overlap: float = 0.3, prefer: np.ndarray | None = None,
) -> dict[int, str]:  # fmt: skip
    """Planes that shadow a plane the views' measured depth prefers, a few centimetres
    beside it.

    A handful of views whose poses are slightly off (a turn-in-place circle registered with a
    0.2 degree error between its photos) put the wall they see a few centimetres in front of
    where every other view puts it, and RANSAC finds that shadow as a plane of its own,
    parallel to the wall and as large in points. The wall is the one the views prefer: with
    ``prefer``, of two such planes the one more views hold more of their measured points on
    (a view's vote between the two; a tilted plane crossing the wall is near it for most
    views, and as many views support both, but each view's points lie on the wall); without
    it, the one more views support (``support``). A tie goes to the one with more points.

    Args:
        planes: the planes, with their extents.
        support: (P,) number of views whose measured depth lies on each plane.
        max_gap_m: parallel planes closer than this are one surface seen twice.
        max_angle_deg: planes within this angle are parallel.
        min_overlap: share of the weaker plane's cells inside the stronger one's extent.
        prefer: (P, P) views that hold more of their measured points on plane i than on
            plane j (:func:`view_preferences`), or None.

    Returns:
        {index: reason} of the shadow planes.
    """
    why: dict[int, str] = {}
    cos_par = np.cos(np.radians(max_angle_deg))
    order = sorted(range(len(planes)), key=lambda j: (-support[j], -planes[j].inliers))

    def votes(i: int, j: int) -> tuple[int, int]:
        if prefer is None:
            return int(support[i]), int(support[j])
        return int(prefer[i, j]), int(prefer[j, i])

    for a, first in enumerate(order):
        for second in order[a + 1 :]:
            if first in why:
                break
            if second in why or abs(planes[first].normal @ planes[second].normal) < cos_par:
                continue
            v1, v2 = votes(first, second)
            if v1 != v2:
                keep, drop = (first, second) if v1 > v2 else (second, first)
            elif planes[first].inliers != planes[second].inliers:  # as many views for both:
                # the one with more points is the surface
                keep, drop = ((first, second) if planes[second].inliers < planes[first].inliers
                              else (second, first))  # fmt: skip
            else:
                continue
            pk, pd = planes[keep], planes[drop]
            gap = abs(pd.origin @ pk.normal + pk.offset)
            if gap > max_gap_m:
                continue
            _, X = pd.cell_centres()
            overlap = float(pk.inside(X).mean()) if len(X) else 0.0
            if overlap >= min_overlap:
                vk, vd = votes(keep, drop)
                said = (f"{vd} views hold more of their points on it, {vk} on the other; "
                        if prefer is not None else "")  # fmt: skip
                why[drop] = (f"shadow of a plane {100 * gap:.1f} cm away ({100 * overlap:.0f}% "
                             f"overlap): {said}seen by {support[drop]} views against "
                             f"{support[keep]}")  # fmt: skip
    return why


def view_preferences(on: np.ndarray, min_points: int) -> np.ndarray:
    """One view's votes between the planes: (P, P) bool, plane i over plane j where the view
    holds more of its measured points on i than on j, and at least ``min_points`` on i.

    Args:
        on: (P,) the view's measured points on each plane (:func:`plane_evidence`).
        min_points: the points that make a view support a plane.
    """
    on = np.asarray(on)
    return (on[:, None] > on[None, :]) & (on[:, None] >= min_points)
