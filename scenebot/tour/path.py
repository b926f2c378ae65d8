"""The tour path: a smooth camera path at camera height along the robot's capture positions.

The photos' camera centres, in capture order, are where the robot actually was: the free space
it drove through. Consecutive centres closer than ``cluster_radius_m`` merge into one waypoint
(a circle of photos taken in place is one stop). A cubic spline (scipy ``splprep``) through the
waypoints, resampled at constant speed, gives the positions; the camera looks along the path
towards a point ``look_ahead_m`` ahead, swaying by ``sweep_deg`` to look around the room.

Every position is checked against the dense cloud (no point within ``clearance_m``
horizontally in the camera's height band) and, when given, the mesh stage's free space. If
the spline leaves the free space, the path falls back to straight segments between the
waypoints (the robot's own tracks); positions that still fail are dropped, and none left is an
error.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import splev, splprep
from scipy.spatial import cKDTree

from scenebot.geometry import look_rotation
from scenebot.tour.camera import TourInputError
from scenebot.tour.config import PathConfig


@dataclass
class TourPath:
    """Camera poses of the tour.

    Attributes:
        positions: (F, 3) camera centres, metres.
        headings: (F,) viewing directions, radians from +x towards +y.
        waypoints: (M, 3) the stops the path passes through, metres.
        kind: ``spline``, ``polyline`` or ``orbit`` (a single stop: turn in place).
        dropped: frames removed because they failed the free-space checks.
    """

    positions: np.ndarray
    headings: np.ndarray
    waypoints: np.ndarray
    kind: str
    dropped: int = 0

    def __len__(self) -> int:
        return len(self.positions)

    def pose(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """cam_from_world (R (3, 3), t (3,)) of frame ``i``."""
        R = look_rotation(float(self.headings[i]))
        return R, -R @ self.positions[i]


def cluster_waypoints(centers: np.ndarray, radius_m: float) -> np.ndarray:
    """Merge consecutive camera centres closer than ``radius_m`` to their stop's mean.

    Args:
        centers: (N, 3) camera centres in capture order, metres.
        radius_m: merge distance, metres.

    Returns:
        (M, 3) waypoints in capture order.
    """
    groups: list[list[np.ndarray]] = []
    for c in np.asarray(centers, np.float64):
        if groups and np.linalg.norm(c - np.mean(groups[-1], axis=0)) < radius_m:
            groups[-1].append(c)
        else:
            groups.append([c])
    return np.array([np.mean(g, axis=0) for g in groups])


class ClearanceChecker:
    """Is a camera position free? Cloud clearance plus an optional free-space test.

    Args:
        points: (N, 3) dense cloud, metres.
        clearance_m: horizontal distance to keep from points in the camera's height band
            (``tour.path.clearance_m``).
        height: camera height (z of the camera plane), metres.
        band_m: half height of the band of points that count as obstacles, metres
            (``tour.path.height_band_m``).
        freespace: optional callable (K, 2) xy -> (K,) bool.
        min_points: points within the clearance that make an obstacle (count;
            ``tour.path.obstacle_min_points``).
    """

    def __init__(self, points, clearance_m, height, band_m, freespace=None, *, min_points):
        pts = np.asarray(points, np.float64)
        near = pts[np.abs(pts[:, 2] - height) < band_m]
        self.tree = cKDTree(near[:, :2]) if len(near) else None
        self.clearance = clearance_m
        self.freespace = freespace
        self.min_points = max(1, int(min_points))

    def ok(self, xy: np.ndarray) -> np.ndarray:
        """(K,) bool for positions (K, 2), metres."""
        xy = np.asarray(xy, np.float64).reshape(-1, 2)
        good = np.ones(len(xy), bool)
        if self.tree is not None and self.clearance > 0:
            # an obstacle is a surface: at least min_points within the clearance, so that a
            # few floaters of the fusion do not block the way
            count = self.tree.query_ball_point(xy, self.clearance, return_length=True)
            good &= np.asarray(count) < self.min_points
        if self.freespace is not None:
            good &= np.asarray(self.freespace(xy), bool)
        return good


def _resample(curve: np.ndarray, n: int) -> np.ndarray:
    """``n`` points at equal arc length along a dense polyline (K, 2)."""
    seg = np.linalg.norm(np.diff(curve, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] <= 0:
        return np.repeat(curve[:1], n, axis=0)
    q = np.linspace(0, s[-1], n)
    return np.stack([np.interp(q, s, curve[:, k]) for k in range(curve.shape[1])], -1)


def _headings(xy: np.ndarray, cfg: PathConfig, fallback: float = 0.0) -> np.ndarray:
    """Look towards the point ``look_ahead_m`` further along the path, swaying by sweep_deg."""
    n = len(xy)
    seg = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    total = s[-1]
    if total < 1e-6:  # a single stop: turn around once
        return fallback + np.linspace(0, 2 * np.pi, n, endpoint=False)
    ahead = np.minimum(s + cfg.look_ahead_m, total)
    target = np.stack([np.interp(ahead, s, xy[:, 0]), np.interp(ahead, s, xy[:, 1])], -1)
    d = target - xy
    # near the end there is nothing ahead: keep the last direction
    last = np.arctan2(*(xy[-1] - xy[max(0, n - 2)])[::-1])
    h = np.where(np.linalg.norm(d, axis=1) > 1e-6, np.arctan2(d[:, 1], d[:, 0]), last)
    h = np.unwrap(h)
    sweep = np.radians(cfg.sweep_deg) * np.sin(2 * np.pi * s / max(4.0, total / 2))
    return h + sweep


def plan_tour(
    centers: np.ndarray,
    cfg: PathConfig,
    checker: ClearanceChecker | None = None,
    start_heading: float = 0.0,
) -> TourPath:
    """The tour through the capture positions.

    Args:
        centers: (N, 3) photo camera centres in capture order, metres.
        cfg: path settings (``frames`` poses are produced before the checks).
        checker: free-space test; None accepts every position.
        start_heading: heading of the first photo, radians (used by the orbit).

    Returns:
        The tour path.

    Raises:
        TourInputError: no camera centres, or no position passes the free-space checks.
    """
    centers = np.asarray(centers, np.float64).reshape(-1, 3)
    if len(centers) == 0:
        raise TourInputError("the map has no registered photo: no positions for a tour path")
    height = float(np.median(centers[:, 2]))
    wp = cluster_waypoints(centers, cfg.cluster_radius_m)
    n = cfg.frames
    kinds = []
    if len(wp) == 1:
        kinds.append(("orbit", np.repeat(wp[:1, :2], n, axis=0)))
    else:
        if len(wp) >= 3:
            k = min(3, len(wp) - 1)
            tck, _ = splprep(wp[:, :2].T, s=cfg.smoothing, k=k)
            dense = np.stack(splev(np.linspace(0, 1, 40 * len(wp)), tck), -1)
            kinds.append(("spline", _resample(dense, n)))
        kinds.append(("polyline", _resample(wp[:, :2], n)))
    best = None
    for kind, xy in kinds:
        good = checker.ok(xy) if checker is not None else np.ones(len(xy), bool)
        if best is None or good.sum() > best[2].sum():
            best = (kind, xy, good)
        if good.all():
            break
    kind, xy, good = best
    if not good.any():
        raise TourInputError(
            f"no tour position keeps {cfg.clearance_m} m from the dense cloud "
            "(tour.path.clearance_m) or lies in the free space: lower tour.path.clearance_m, "
            "set tour.path.use_freespace false, or check the map"
        )
    heads = _headings(xy, cfg, start_heading)
    pos = np.concatenate([xy, np.full((len(xy), 1), height)], 1)
    return TourPath(pos[good], heads[good], wp, kind, int((~good).sum()))
