"""The tour path: a smooth walk through the photos' positions that looks at what they show.

1. Stops: camera centres closer than a radius merge into one stop (a circle of photos taken
   in place, or a person's photos from one spot, is one stop).
2. Order: the shortest closed tour through the stops (nearest neighbour, then 2-opt and
   or-opt moves), not the capture order (whose legs cross the room); legs that
   cross an obstacle cost ``blocked_cost`` times their length. The loop is opened at its
   longest leg when that leg is ``open_gap`` times the median leg (a ring of photos with a
   gap, a walk along a facade), so the tour never jumps across the scene.
3. Curve: a cubic spline (periodic when closed; scipy ``splprep``) through the ordered stops,
   resampled at constant speed; the view turns by at most ``max_turn_deg`` per frame.
4. View: each photo looks at a *target*, the dense model's mass in front of it (its median
   visible depth along its axis; see :meth:`scenebot.tour.ulr.UlrRenderer.source_targets`).
   A path point looks at the mean target of the stops near it (Gaussian weights over the
   distance, ``look_bandwidth`` median legs wide). Where a stop's photos agree on a
   direction (a ring around an object, a fan towards a corner, a walk along a facade) the
   tour looks where they look; where they look every way (a robot's circle of photos) it
   looks along the path, swaying by ``sweep_deg``; the blend weight is the agreement (length
   of the photos' mean unit viewing direction). The directions are then smoothed along the
   path (``look_smoothing``) and their turn per frame limited (``max_turn_deg``).

Obstacles: the stops are first moved clear of the cloud (the cameras stood there); where the
curve still comes within the clearance (or leaves the free space), it gets an extra control
point at the nearest free position and is fitted again (:func:`free_curve`); no position
moves more than twice the smaller of the clearance and the stop radius, so the path stays
where the photos were; if straight legs do better, they are used; positions that still fail
are dropped.

Robot (``photos=False``): the path lies in the camera plane (the median camera height),
the camera is level and lengths are metres; each position keeps ``clearance_m`` from the
dense cloud in the camera's height band and, when given, stays in the mesh stage's free
space.

A person's photos (``photos=True``): six degrees of freedom, +z up: the path is 3-D through
the camera centres, the camera pitches towards the target (no roll), the clearance from the
cloud is a 3-D distance, and there is no free space. No metric scale is assumed: the stage
hands this module settings whose lengths are scaled to the scene
(:func:`scenebot.tour.stage.photo_units`), so the same values work in any unit.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import splev, splprep
from scipy.ndimage import gaussian_filter1d
from scipy.spatial import cKDTree

from scenebot.geometry import look_rotation
from scenebot.tour.camera import TourInputError
from scenebot.tour.config import PathConfig


@dataclass
class TourPath:
    """Camera poses of the tour.

    Attributes:
        positions: (F, 3) camera centres (metres; SfM units for a person's photos).
        headings: (F,) viewing directions, radians from +x towards +y.
        waypoints: (M, 3) the stops, in tour order.
        kind: ``spline``, ``polyline`` or ``orbit`` (a single stop: turn in place).
        dropped: frames removed because they failed the clearance/free-space checks.
        pitches: (F,) upward tilt of the view, radians (0: level).
        targets: (F, 3) the look-at point of each frame (NaN where the view follows the path).
        closed: whether the tour is a loop.
    """

    positions: np.ndarray
    headings: np.ndarray
    waypoints: np.ndarray
    kind: str
    dropped: int = 0
    pitches: np.ndarray = field(default=None)  # type: ignore[assignment]
    targets: np.ndarray = field(default=None)  # type: ignore[assignment]
    closed: bool = False

    def __post_init__(self):
        n = len(self.positions)
        if self.pitches is None:
            self.pitches = np.zeros(n)
        if self.targets is None:
            self.targets = np.full((n, 3), np.nan)

    def __len__(self) -> int:
        return len(self.positions)

    def pose(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """cam_from_world (R (3, 3), t (3,)) of frame ``i``."""
        R = look_rotation(float(self.headings[i]), float(self.pitches[i]))
        return R, -R @ self.positions[i]

    def forward(self) -> np.ndarray:
        """(F, 3) unit viewing directions."""
        cp = np.cos(self.pitches)
        return np.stack(
            [cp * np.cos(self.headings), cp * np.sin(self.headings), np.sin(self.pitches)], -1
        )

    def subset(self, keep: np.ndarray) -> TourPath:
        """The frames where ``keep`` (F,) bool is true; the others count as dropped."""
        keep = np.asarray(keep, bool)
        return TourPath(
            self.positions[keep],
            self.headings[keep],
            self.waypoints,
            self.kind,
            self.dropped + int((~keep).sum()),
            self.pitches[keep],
            self.targets[keep],
            self.closed,
        )


def cluster_waypoints(centers: np.ndarray, radius: float) -> np.ndarray:
    """Merge camera centres within ``radius`` of a stop's running mean into that stop.

    Args:
        centers: (N, 3) camera centres in capture order.
        radius: merge distance (same unit as the centres).

    Returns:
        (M, 3) stops, in the order of their first photo.
    """
    return _cluster(centers, radius)[0]


def _cluster(centers: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Stops (M, 3) and the stop of every centre (N,) (greedy leader clustering)."""
    sums: list[np.ndarray] = []
    counts: list[int] = []
    label = np.zeros(len(centers), np.int64)
    for n, c in enumerate(np.asarray(centers, np.float64)):
        if sums:
            means = np.array(sums) / np.array(counts)[:, None]
            d = np.linalg.norm(means - c, axis=1)
            m = int(np.argmin(d))
            if d[m] < radius:
                sums[m] = sums[m] + c
                counts[m] += 1
                label[n] = m
                continue
        sums.append(c.copy())
        counts.append(1)
        label[n] = len(sums) - 1
    return np.array(sums) / np.array(counts)[:, None], label


class ClearanceChecker:
    """Is a camera position free? Cloud clearance plus an optional free-space test.

    Args:
        points: (N, 3) dense cloud.
        clearance_m: distance to keep from the points (``tour.path.clearance_m``).
        height: camera height (z of the camera plane); None: a 3-D ball test, no height band.
        band_m: half height of the band of points that count as obstacles, metres
            (``tour.path.height_band_m``; unused for a 3-D test).
        freespace: optional callable (K, 2) xy -> (K,) bool.
        min_points: points within the clearance that make an obstacle (count;
            ``tour.path.obstacle_min_points``).
    """

    def __init__(self, points, clearance_m, height, band_m, freespace=None, *, min_points):
        pts = np.asarray(points, np.float64).reshape(-1, 3)
        self.planar = height is not None
        near = pts[np.abs(pts[:, 2] - height) < band_m][:, :2] if self.planar else pts
        self.tree = cKDTree(near) if len(near) else None
        self.clearance = clearance_m
        self.freespace = freespace
        self.min_points = max(1, int(min_points))

    def passable(self, pos: np.ndarray) -> np.ndarray:
        """(K,) bool: not inside an obstacle: in the free space when there is one, else clear
        of the cloud (the legs between stops are judged by this)."""
        if self.freespace is not None:
            pos = np.asarray(pos, np.float64)
            return np.asarray(self.freespace(pos.reshape(-1, pos.shape[-1])[:, :2]), bool)
        return self.ok(pos)

    def ok(self, pos: np.ndarray) -> np.ndarray:
        """(K,) bool for positions (K, 2) (planar test) or (K, 3)."""
        pos = np.asarray(pos, np.float64)
        pos = pos.reshape(-1, pos.shape[-1])
        xy = pos[:, :2]
        good = np.ones(len(pos), bool)
        if self.tree is not None and self.clearance > 0:
            q = xy if self.planar else pos
            # an obstacle is a surface: at least min_points within the clearance, so that a
            # few floaters of the fusion do not block the way
            count = self.tree.query_ball_point(q, self.clearance, return_length=True)
            good &= np.asarray(count) < self.min_points
        if self.freespace is not None:
            good &= np.asarray(self.freespace(xy), bool)
        return good


def snap_free(pos: np.ndarray, checker: ClearanceChecker, max_shift: float) -> np.ndarray:
    """Move positions that fail the checker to the nearest free position within ``max_shift``.

    Candidates lie on rings (a sphere's directions for 3-D positions) at 8 distances up to
    ``max_shift``; a position with no free candidate stays where it is.

    Args:
        pos: (K, 2) or (K, 3) positions.
        checker: the clearance/free-space test.
        max_shift: the largest move (same unit as the positions).

    Returns:
        (K, D) positions.
    """
    pos = np.array(pos, np.float64)
    bad = np.flatnonzero(~checker.ok(pos))
    if len(bad) == 0 or max_shift <= 0:
        return pos
    dim = pos.shape[1]
    if dim == 2:
        a = np.linspace(0, 2 * np.pi, 24, endpoint=False)
        dirs = np.stack([np.cos(a), np.sin(a)], -1)
    else:  # a Fibonacci sphere
        k = np.arange(48) + 0.5
        z = 1 - 2 * k / 48
        r = np.sqrt(1 - z * z)
        phi = np.pi * (3 - np.sqrt(5)) * k
        dirs = np.stack([r * np.cos(phi), r * np.sin(phi), z], -1)
    radii = max_shift * np.arange(1, 9) / 8
    offs = (radii[:, None, None] * dirs[None]).reshape(-1, dim)  # nearest rings first
    for i in bad:
        cand = pos[i] + offs
        ok = np.flatnonzero(checker.ok(cand))
        if len(ok):
            pos[i] = cand[ok[0]]
    return pos


# --------------------------------------------------------------------------- tour order
def _leg_costs(wp: np.ndarray, checker: ClearanceChecker | None, blocked_cost: float):
    """(M, M) leg lengths, times ``blocked_cost`` where a straight leg crosses an obstacle
    (leaves the free space; without one, comes within the clearance of the cloud)."""
    d = np.linalg.norm(wp[:, None] - wp[None], axis=2)
    if checker is None or blocked_cost <= 1 or len(wp) < 3:
        return d
    cost = d.copy()
    # only the legs a short tour can use: each stop's nearest neighbours
    k = min(len(wp) - 1, 8)
    nb = np.argsort(d, axis=1)[:, 1 : k + 1]
    frac = np.linspace(0.1, 0.9, 9)
    for a in range(len(wp)):
        for b in nb[a]:
            if b < a and b in nb[b] and a in nb[b]:
                continue  # done from the other side
            pts = wp[a] + frac[:, None] * (wp[b] - wp[a])
            dim = 2 if checker.planar else 3
            if not checker.passable(pts[:, :dim]).all():
                cost[a, b] = cost[b, a] = d[a, b] * blocked_cost
    return cost


def _tour_length(order: np.ndarray, cost: np.ndarray) -> float:
    return float(cost[order, np.roll(order, -1)].sum())


def _two_opt(tour: np.ndarray, cost: np.ndarray) -> bool:
    """Reverse sub-paths of the closed tour (in place) while that shortens it.

    Returns:
        Whether the tour changed.
    """
    m = len(tour)
    changed = False
    improved = True
    while improved:
        improved = False
        for i in range(m - 1):
            a, b = tour[i], tour[i + 1]
            j = np.arange(i + 2, m if i > 0 else m - 1)
            if len(j) == 0:
                continue
            c, d = tour[j], tour[(j + 1) % m]
            delta = cost[a, c] + cost[b, d] - cost[a, b] - cost[c, d]
            best = int(np.argmin(delta))
            if delta[best] < -1e-9:
                jj = j[best]
                tour[i + 1 : jj + 1] = tour[i + 1 : jj + 1][::-1].copy()
                improved = changed = True
    return changed


def _or_opt(tour: np.ndarray, cost: np.ndarray) -> bool:
    """Move runs of 1-3 consecutive stops (either way round) to the best other place in the
    closed tour (in place) while that shortens it.

    Returns:
        Whether the tour changed.
    """
    m = len(tour)
    changed = False
    for length in (1, 2, 3):
        if m < length + 3:
            break
        for i in range(m):
            rolled = np.roll(tour, -i)
            seg, rest = rolled[:length], rolled[length:]  # rest starts after the run
            prev, nxt = rest[-1], rest[0]
            gain = cost[prev, seg[0]] + cost[seg[-1], nxt] - cost[prev, nxt]
            a, b = rest[:-1], rest[1:]  # insert between a and b (elsewhere than it was)
            base = cost[a, b]
            fwd = cost[a, seg[0]] + cost[seg[-1], b] - base
            rev = cost[a, seg[-1]] + cost[seg[0], b] - base
            kf, kr = int(np.argmin(fwd)), int(np.argmin(rev))
            flip = rev[kr] < fwd[kf]
            k, best = (kr, rev[kr]) if flip else (kf, fwd[kf])
            if best < gain - 1e-9:
                ins = seg[::-1] if flip else seg
                tour[:] = np.concatenate([rest[: k + 1], ins, rest[k + 1 :]])
                changed = True
    return changed


def short_tour(cost: np.ndarray, start: int = 0) -> np.ndarray:
    """A short closed tour through all stops: nearest neighbour from ``start``, then 2-opt
    and or-opt moves.

    Args:
        cost: (M, M) symmetric leg costs.
        start: the first stop.

    Returns:
        (M,) the order of the stops, starting at ``start``.
    """
    m = len(cost)
    if m <= 3:
        return np.roll(np.arange(m), -start) if m else np.arange(0)
    order = [start]
    free = np.ones(m, bool)
    free[start] = False
    for _ in range(m - 1):
        c = np.where(free, cost[order[-1]], np.inf)
        nxt = int(np.argmin(c))
        order.append(nxt)
        free[nxt] = False
    tour = np.array(order)
    for _ in range(100):  # 2-opt and or-opt until neither improves the tour
        if not (_two_opt(tour, cost) | _or_opt(tour, cost)):
            break
    k = int(np.flatnonzero(tour == start)[0])
    return np.roll(tour, -k)


def order_stops(
    wp: np.ndarray, cost: np.ndarray, start: int, open_gap: float
) -> tuple[np.ndarray, bool]:
    """The stops' tour order and whether it is a closed loop.

    The shortest closed tour is opened at its longest leg when that leg is more than
    ``open_gap`` times the median leg; the open tour then starts at the end nearer to
    ``start`` (the first photo's stop).

    Returns:
        (order (M,), closed).
    """
    m = len(wp)
    if m <= 2:
        return np.roll(np.arange(m), -start), False
    tour = short_tour(cost, start)
    legs = cost[tour, np.roll(tour, -1)]
    worst = int(np.argmax(legs))
    if m >= 3 and legs[worst] <= open_gap * np.median(legs):
        return tour, True
    tour = np.roll(tour, -(worst + 1))  # the longest leg becomes last -> dropped
    if np.linalg.norm(wp[tour[-1]] - wp[start]) < np.linalg.norm(wp[tour[0]] - wp[start]):
        tour = tour[::-1]
    return tour, False


def fit_curve(
    pts: np.ndarray, closed: bool, kind: str, smooth: float, n: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` points at constant speed along a curve through the control points.

    Args:
        pts: (M, D) control points in order.
        closed: a loop (periodic spline; the polyline returns to its start).
        kind: ``spline`` (cubic; scipy ``splprep``, chord-length parameter) or ``polyline``.
        smooth: spline smoothing (``splprep``'s s; 0 interpolates).
        n: samples.

    Returns:
        (n, D) samples, (n,) their curve parameter in [0, 1] and (M,) the control points'.
    """
    data = np.concatenate([pts, pts[:1]]) if closed else pts
    m = len(data)
    seg = np.linalg.norm(np.diff(data, axis=0), axis=1)
    u_ctrl = np.concatenate([[0.0], np.cumsum(seg)])
    u_ctrl = u_ctrl / max(u_ctrl[-1], 1e-12)
    uu = np.linspace(0, 1, 40 * m)
    if kind == "spline" and len(pts) >= 3:
        tck, _ = splprep(data.T, u=u_ctrl, s=smooth, k=min(3, m - 1), per=int(closed))
        dense = np.stack(splev(uu, tck), -1)
    else:
        dense = np.stack([np.interp(uu, u_ctrl, data[:, k]) for k in range(data.shape[1])], -1)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(dense, axis=0), axis=1))])
    q = np.linspace(0, arc[-1], n)
    u_n = np.interp(q, arc, uu)
    xy = np.stack([np.interp(q, arc, dense[:, k]) for k in range(dense.shape[1])], -1)
    return xy, u_n, u_ctrl[: len(pts)]


def free_curve(
    pts: np.ndarray,
    closed: bool,
    kind: str,
    smooth: float,
    n: int,
    checker: ClearanceChecker | None,
    max_shift: float,
    rounds: int = 6,
) -> tuple[np.ndarray, np.ndarray]:
    """The curve of :func:`fit_curve`, bent out of the obstacles.

    Each round, every run of samples that fails the checker gets one more control point: its
    middle sample moved to the nearest free position (:func:`snap_free`, at most
    ``max_shift`` away), and the curve is fitted again; it stays smooth and at constant speed.

    Returns:
        (n, D) samples and (n,) bool whether each passes the checker.
    """
    pts = np.asarray(pts, np.float64)
    for _ in range(rounds + 1):
        xy, u_n, u_ctrl = fit_curve(pts, closed, kind, smooth, n)
        if checker is None:
            return xy, np.ones(n, bool)
        good = checker.ok(xy)
        if good.all():
            break
        bad = np.flatnonzero(~good)
        runs = np.split(bad, np.flatnonzero(np.diff(bad) > 1) + 1)
        mids = np.array([r[len(r) // 2] for r in runs])
        moved = snap_free(xy[mids], checker, max_shift)
        fixed = checker.ok(moved)
        if not fixed.any():
            break
        new_u = u_n[mids[fixed]]
        all_u = np.concatenate([u_ctrl, new_u])
        all_p = np.concatenate([pts, moved[fixed]])
        order = np.argsort(all_u, kind="stable")
        keep = np.concatenate([[True], np.diff(all_u[order]) > 1e-9])  # no double parameter
        pts = all_p[order][keep]
    return xy, good


# --------------------------------------------------------------------------- view directions
def _travel(pos: np.ndarray, closed: bool) -> np.ndarray:
    """(F, 3) unit travel directions (central differences; wrap-around when closed)."""
    if len(pos) < 2:
        return np.tile([1.0, 0.0, 0.0], (len(pos), 1))
    if closed:
        d = np.roll(pos, -1, axis=0) - np.roll(pos, 1, axis=0)
    else:
        d = np.gradient(pos, axis=0)
    n = np.linalg.norm(d, axis=1, keepdims=True)
    return np.where(n > 1e-12, d / np.maximum(n, 1e-12), [1.0, 0.0, 0.0])


def look_targets(
    pos: np.ndarray,
    centers: np.ndarray,
    targets: np.ndarray,
    stop: np.ndarray,
    bandwidth: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The photos' mean target seen from each path point, and how much they agree.

    Per stop: the mean target of its photos and their agreement ``R`` (the length of their
    mean unit viewing direction: 1 when they all look the same way, about 0 for a circle of
    photos). A path point weighs the stops by a Gaussian over its distance to them, and
    each stop's target also by its ``R``, so photos that look every way do not steer it.

    Args:
        pos: (F, 3) path points.
        centers: (N, 3) photo centres.
        targets: (N, 3) the point each photo looks at.
        stop: (N,) the stop of each photo.
        bandwidth: Gaussian width over the distance from a path point to a stop.

    Returns:
        (F, 3) mean targets (NaN where no stop agrees) and (F,) agreement in [0, 1].
    """
    f = targets - centers
    f /= np.maximum(np.linalg.norm(f, axis=1, keepdims=True), 1e-12)
    _, inv = np.unique(stop, return_inverse=True)
    count = np.bincount(inv).astype(np.float64)[:, None]
    at = np.stack([np.bincount(inv, centers[:, k]) for k in range(3)], -1) / count
    tgt = np.stack([np.bincount(inv, targets[:, k]) for k in range(3)], -1) / count
    agree = np.linalg.norm(np.stack([np.bincount(inv, f[:, k]) for k in range(3)], -1), axis=1)
    agree = agree / count[:, 0]
    d2 = ((pos[:, None, :] - at[None]) ** 2).sum(-1)
    # weights relative to the nearest stop, so that far path points still see one
    d2 -= d2.min(axis=1, keepdims=True)
    w = np.exp(-0.5 * d2 / max(bandwidth, 1e-12) ** 2)
    wa = w * agree[None]
    a = wa.sum(1) / w.sum(1)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = (wa @ tgt) / wa.sum(1, keepdims=True)
    return mean, a


def view_directions(
    pos: np.ndarray,
    centers: np.ndarray,
    targets: np.ndarray | None,
    stop: np.ndarray,
    cfg: PathConfig,
    bandwidth: float,
    closed: bool,
    level: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """Smoothed unit viewing directions (F, 3) and look-at points (F, 3) (NaN: path).

    See the module docstring and :func:`look_targets` (``stop``: (N,) each photo's stop);
    ``level`` keeps the camera horizontal (the robot).
    """
    n = len(pos)
    travel = _travel(pos, closed)
    if level:
        travel[:, 2] = 0
    seg = np.linalg.norm(np.diff(pos, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    total = s[-1]
    if total > 1e-9:
        # the travel direction sways twice along the path to look about
        ang = np.radians(cfg.sweep_deg) * np.sin(4 * np.pi * s / total)
        c, sn = np.cos(ang), np.sin(ang)
        travel = np.stack(
            [c * travel[:, 0] - sn * travel[:, 1], sn * travel[:, 0] + c * travel[:, 1],
             travel[:, 2]], -1)  # fmt: skip
    look = np.full((n, 3), np.nan)
    if targets is None:
        v = travel
    else:
        tgt, agree = look_targets(pos, centers, targets, stop, bandwidth)
        to_t = np.nan_to_num(tgt - pos)
        if level:
            to_t[:, 2] = 0
        norm = np.linalg.norm(to_t, axis=1, keepdims=True)
        a = np.clip(agree, 0, 1)[:, None] * (norm > 1e-9)
        v = a * to_t / np.maximum(norm, 1e-12) + (1 - a) * travel
        look = np.where(a > 0.5, tgt, np.nan)
    if level:
        v[:, 2] = 0
    # smooth along the path (wrapping around a loop)
    sigma = cfg.look_smoothing * n
    if sigma > 0 and n > 2:
        v = gaussian_filter1d(v, sigma, axis=0, mode="wrap" if closed else "nearest")
    nv = np.linalg.norm(v, axis=1, keepdims=True)
    v = np.where(nv > 1e-9, v / np.maximum(nv, 1e-12), travel)
    return v, look


def turn_limit(heading: np.ndarray, pitch: np.ndarray, max_turn_deg: float) -> float:
    """The largest turn per frame, radians: ``max_turn_deg``, or twice the mean turn per
    frame of the wanted view where that is more (a short tour that must turn a lot).

    Args:
        heading: (F,) wanted unwrapped headings, radians.
        pitch: (F,) wanted pitches, radians.
        max_turn_deg: ``tour.path.max_turn_deg``.
    """
    if len(heading) < 2:
        return np.radians(max_turn_deg)
    mean = max(np.abs(np.diff(heading)).mean(), np.abs(np.diff(pitch)).mean())
    return float(max(np.radians(max_turn_deg), 2 * mean))


def limit_rate(angle: np.ndarray, limit: float) -> np.ndarray:
    """An angle sequence that follows ``angle`` but changes by at most ``limit`` per step.

    The mean of a forward and a backward rate-limited follower: no lag either way, and the
    mean of two sequences with steps <= limit has steps <= limit.

    Args:
        angle: (F,) unwrapped angles, radians.
        limit: largest step, radians.

    Returns:
        (F,) angles, radians.
    """
    n = len(angle)
    if n < 2:
        return np.asarray(angle, np.float64)
    fwd = np.empty(n)
    bwd = np.empty(n)
    fwd[0], bwd[-1] = angle[0], angle[-1]
    for i in range(1, n):
        fwd[i] = fwd[i - 1] + np.clip(angle[i] - fwd[i - 1], -limit, limit)
        j = n - 1 - i
        bwd[j] = bwd[j + 1] + np.clip(angle[j] - bwd[j + 1], -limit, limit)
    return 0.5 * (fwd + bwd)


# --------------------------------------------------------------------------- the tour
def plan_tour(
    centers: np.ndarray,
    cfg: PathConfig,
    checker: ClearanceChecker | None = None,
    start_heading: float = 0.0,
    *,
    targets: np.ndarray | None = None,
    photos: bool = False,
) -> TourPath:
    """The tour through the capture positions.

    Args:
        centers: (N, 3) photo camera centres in capture order.
        cfg: path settings (``frames`` poses are produced before the checks).
        checker: free-space test; None accepts every position.
        start_heading: heading of the first photo, radians (used by the orbit).
        targets: (N, 3) the point each photo looks at; None: the tour looks along the path.
        photos: a person's photos (3-D path, pitched camera, lengths from the scene) rather
            than the robot's (level camera in the camera plane, metres).

    Returns:
        The tour path.

    Raises:
        TourInputError: no camera centres, or no position passes the free-space checks.
    """
    centers = np.asarray(centers, np.float64).reshape(-1, 3)
    if len(centers) == 0:
        raise TourInputError("the map has no registered photo: no positions for a tour path")
    if targets is not None:
        targets = np.asarray(targets, np.float64).reshape(-1, 3)
        seen = np.all(np.isfinite(targets), axis=1)  # a photo that sees nothing has no say
    else:
        seen = np.zeros(len(centers), bool)
    wp, label = _cluster(centers, cfg.cluster_radius_m)
    look_t = targets[seen] if seen.any() else None
    height = float(np.median(centers[:, 2]))
    dim = 3 if photos else 2
    n = cfg.frames
    if len(wp) == 1:
        pos = np.repeat(wp[:1], n, axis=0)
        if not photos:
            pos[:, 2] = height
        heads = start_heading + np.linspace(0, 2 * np.pi, n, endpoint=False)
        return TourPath(pos, heads, wp, "orbit", 0, np.zeros(n), None, True)
    pts = wp[:, :dim]
    # how far the path may bend away from the photos to clear the cloud
    shift = 2 * min(checker.clearance, cfg.cluster_radius_m) if checker is not None else 0.0
    if checker is not None:  # the cameras stood at the stops: move them clear of the cloud
        pts = snap_free(pts, checker, shift)
    cost = _leg_costs(pts, checker, cfg.blocked_cost)
    order, closed = order_stops(pts, cost, int(label[0]), cfg.open_gap)
    pts, wp = pts[order], wp[order]
    legs = np.linalg.norm(
        np.diff(np.concatenate([pts, pts[:1]]) if closed else pts, axis=0), axis=1
    )
    leg = float(np.median(legs))
    smooth = len(wp) * (cfg.smoothing * leg) ** 2
    best = None
    for kind in ("spline", "polyline") if len(wp) >= 3 else ("polyline",):
        xy, good = free_curve(pts, closed, kind, smooth, n, checker, shift)
        if best is None or good.sum() > best[2].sum():
            best = (kind, xy, good)
        if good.all():
            break
    kind, xy, good = best
    if not good.any():
        raise TourInputError(
            f"no tour position keeps {checker.clearance:.3g} from the dense cloud "
            "(tour.path.clearance_m; for a person's photos scaled by tour.photos_depth_m) or "
            "lies in the free space: lower it, set tour.path.use_freespace false, or check the "
            "map"
        )
    if photos:
        pos = xy
    else:
        pos = np.concatenate([xy, np.full((len(xy), 1), height)], 1)
    v, look = view_directions(
        pos,
        centers[seen],
        look_t,
        label[seen],
        cfg,
        cfg.look_bandwidth * leg,
        closed,
        level=not photos,
    )
    heads = np.unwrap(np.arctan2(v[:, 1], v[:, 0]))
    pitch = np.arcsin(np.clip(v[:, 2], -1, 1)) if photos else np.zeros(len(v))
    limit = turn_limit(heads, pitch, cfg.max_turn_deg)
    heads, pitch = limit_rate(heads, limit), limit_rate(pitch, limit)
    path = TourPath(pos, heads, wp, kind, 0, pitch, look, closed)
    return path.subset(good)
