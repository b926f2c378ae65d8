"""Bring an SfM model into the robot frame: camera centres on z = 0, z up, metres, compass heading.

The robot frame is the odometry frame of round 0: origin where the robot was when it took
its first photo (minus the camera offset), x axis along compass heading 0, z up. Steps
(:func:`robot_frame_transform`):

1. **Plane**: robust plane fit to the camera centres (iteratively trimmed SVD); when the
   centres are nearly collinear the mean camera up vector is the normal. The normal's sign
   is chosen so that it agrees with the cameras' up vectors (-y axis of OpenCV cameras).
2. **Heading**: the yaw that best maps the cameras' viewing directions onto the compass
   headings (robust circular mean), with ``camera_yaw_deg`` for a camera not looking forward.
3. **Scale**: with the camera's known lever arm (``camera_offset_m``, the camera centre's
   distance from the rotation axis), from the circles of photos turned in place: their
   camera centres lie on circles of that radius whatever the wheels slip
   (:func:`fit_scale_to_circles`). Otherwise (and always as a cross-check, in the stats)
   from odometry: the camera's offset from photo pairs of turns in place, then a robust fit
   of odometry drive distances to the SfM robot displacements (lengths only, so heading
   drift of odometry from slip on turns does not bias it); see
   :func:`fit_scale_to_odometry`. Drive distances carry the wheels' drive slip (2 % in
   the simulator) and rest on few drive legs.
4. **Translation**: z so that the centres' median height is 0; x, y from the previous
   round's model (median over shared photos) or from round 0's first photo's odometry.

Only logged odometry/compass and the model itself are used, never the simulator's truth.
"""

from __future__ import annotations

import itertools
import logging
import math
from dataclasses import asdict, dataclass, field

import numpy as np
import pycolmap

from scenebot.sfm.photos import Photo

log = logging.getLogger(__name__)


@dataclass
class Alignment:
    """The similarity ``x_robot = scale * R @ x_sfm + t`` and how it was found.

    Attributes:
        scale: metres per SfM unit.
        R: (3, 3) rotation.
        t: (3,) translation (m).
        scale_source: ``camera_lever_arm``, ``odometry``, ``known_distance``,
            ``previous_model`` or ``none``.
        heading_source: ``compass``, ``odometry``, ``previous_model`` or ``first_photo``.
        camera_offset_m: camera centre in the robot's frame (forward, left) (m) from the
            lever-arm or odometry fit, or ``None``.
        stats: fit residuals (plane rms (m), heading residual (deg), odometry residual (m), counts).
    """

    scale: float
    R: np.ndarray
    t: np.ndarray
    scale_source: str
    heading_source: str
    camera_offset_m: tuple[float, float] | None = None
    stats: dict = field(default_factory=dict)

    def sim3d(self) -> pycolmap.Sim3d:
        return pycolmap.Sim3d(self.scale, pycolmap.Rotation3d(self.R), self.t.reshape(3, 1))

    def as_dict(self) -> dict:
        d = asdict(self)
        d["R"] = self.R.tolist()
        d["t"] = self.t.tolist()
        return d


def _wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def _rot_to_z(n: np.ndarray) -> np.ndarray:
    """Rotation (3, 3) taking unit vector ``n`` to +z (Rodrigues)."""
    z = np.array([0.0, 0.0, 1.0])
    v = np.cross(n, z)
    s, c = np.linalg.norm(v), float(n @ z)
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    k = v / s
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + s * K + (1 - c) * K @ K


def _rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def fit_plane_normal(centers: np.ndarray, ups: np.ndarray) -> tuple[np.ndarray, dict]:
    """Robust up direction of the plane through the camera centres.

    Args:
        centers: (N, 3) camera centres.
        ups: (N, 3) camera up vectors (unit).

    Returns:
        Unit normal (3,) pointing the way the cameras' up vectors point, and stats.
    """
    mean_up = ups.mean(0)
    mean_up /= np.linalg.norm(mean_up)
    # the first inliers: the centres near the plane the cameras' up vectors say (photos
    # registered metres off, not yet left out, would tilt a first fit through every centre,
    # and the trimming could then settle on that tilt: 1.6 deg in a generated room's round)
    r = np.abs((centers - np.median(centers, 0)) @ mean_up)
    keep = r <= max(3.0 * 1.4826 * float(np.median(r)), 1e-9)
    n = mean_up
    sv = np.zeros(3)
    for _ in range(4):
        if keep.sum() < 3:
            break
        c0 = np.median(centers[keep], 0)
        _, sv, vt = np.linalg.svd(centers[keep] - c0, full_matrices=False)
        n = vt[-1]
        r = np.abs((centers - c0) @ n)
        sigma = 1.4826 * np.median(r[keep]) + 1e-12
        keep = r <= max(3.0 * sigma, 1e-9)
    degenerate = len(sv) < 2 or sv[1] < 0.05 * sv[0] or keep.sum() < 3
    if degenerate:
        n = mean_up
    if n @ mean_up < 0:
        n = -n
    tilt = math.degrees(math.acos(np.clip(float(n @ mean_up), -1, 1)))
    return n, {"plane_degenerate": bool(degenerate), "camera_up_tilt_deg": tilt}


def robust_circular_mean(a: np.ndarray) -> float:
    """Circular mean of angles ``a`` (rad) after dropping outliers (> 3 robust sigma)."""
    m = math.atan2(np.sin(a).mean(), np.cos(a).mean())
    for _ in range(3):
        r = np.abs(_wrap(a - m))
        sigma = max(1.4826 * float(np.median(r)), math.radians(0.5))
        sel = r <= 3 * sigma
        m = math.atan2(np.sin(a[sel]).mean(), np.cos(a[sel]).mean())
    return m


def fit_scale_to_odometry(
    dc: np.ndarray, h_i: np.ndarray, h_j: np.ndarray, dp: np.ndarray
) -> tuple[float, np.ndarray, dict]:
    """Metric scale and camera offset from consecutive photo pairs.

    Model: ``scale * dc = dr + (R(h_j) - R(h_i)) @ o`` where ``dr`` is the robot's
    displacement and ``o`` the camera centre in the robot frame. Two robust steps:

    1. pairs where the robot turned in place (``|dp| < 1 cm``) give ``o / scale`` from
       ``dc = (R(h_j) - R(h_i)) @ (o / scale)`` (Huber IRLS);
    2. pairs where the robot drove (``|dp| > 5 cm``) give the scale as the ratio of the
       odometry distance to the SfM robot displacement ``|dc - (R(h_j) - R(h_i)) o/scale|``
       (distances only: odometry's heading drift from slip on turns does not matter),
       combined by distance-weighted least squares after rejecting ratios beyond 3 robust
       sigma.

    Args:
        dc: (M, 2) SfM camera displacements (SfM units, heading-aligned frame).
        h_i, h_j: (M,) robot headings (rad) at the two photos.
        dp: (M, 2) odometry robot displacements (m); only their lengths are used.

    Returns:
        ``scale`` (m per unit), camera offset ``o`` (2,) in the robot frame (m), stats.
    """
    dcos = np.cos(h_j) - np.cos(h_i)
    dsin = np.sin(h_j) - np.sin(h_i)
    dist = np.linalg.norm(dp, axis=1)
    turn = dist < 0.01
    o_unit = np.zeros(2)
    if turn.sum() >= 2:
        A = np.zeros((2 * turn.sum(), 2))
        A[0::2] = np.stack([dcos[turn], -dsin[turn]], 1)
        A[1::2] = np.stack([dsin[turn], dcos[turn]], 1)
        b = dc[turn].reshape(-1)
        w = np.ones(turn.sum())
        for _ in range(10):
            ww = np.repeat(np.sqrt(w), 2)
            o_unit, *_ = np.linalg.lstsq(A * ww[:, None], b * ww, rcond=None)
            r = np.linalg.norm((A @ o_unit - b).reshape(-1, 2), axis=1)
            delta = max(1.4826 * float(np.median(r)) * 1.5, 1e-12)
            w = np.minimum(1.0, delta / np.maximum(r, 1e-15))
    move = dist > 0.05
    if move.sum() < 1:
        raise ValueError("no photo pair with the robot driving > 5 cm: scale not observable")
    ro = np.stack([dcos * o_unit[0] - dsin * o_unit[1], dsin * o_unit[0] + dcos * o_unit[1]], 1)
    dr = np.linalg.norm(dc - ro, axis=1)[move]
    dm = dist[move]
    ratio = dm / np.maximum(dr, 1e-15)
    med = float(np.median(ratio))
    sigma = max(1.4826 * float(np.median(np.abs(ratio - med))), 1e-3 * med)
    inl = np.abs(ratio - med) <= 3 * sigma
    scale = float((dm[inl] * dr[inl]).sum() / (dr[inl] ** 2).sum())
    stats = {
        "odometry_pairs": len(dc),
        "odometry_turn_pairs": int(turn.sum()),
        "odometry_drive_pairs": int(move.sum()),
        "odometry_outlier_pairs": int((~inl).sum()),
        "odometry_distance_residual_median_m": float(np.median(np.abs(scale * dr - dm))),
    }
    return scale, scale * o_unit, stats


def _heading_span(h: np.ndarray) -> float:
    """Angular span (rad) covered by headings ``h`` (rad): 2 pi minus the largest gap."""
    a = np.sort(np.mod(h, 2 * np.pi))
    if len(a) < 2:
        return 0.0
    gaps = np.diff(np.r_[a, a[0] + 2 * np.pi])
    return float(2 * np.pi - gaps.max())


def _fit_circles_lever_arm(
    xy: np.ndarray, h: np.ndarray, groups: list[np.ndarray], iterations: int = 10
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Joint robust fit of ``xy[k] = p[c] + R(h[k]) @ u`` over the photos of circles ``c``.

    Args:
        xy: (N, 2) camera centres (any units, heading-aligned horizontal frame).
        h: (N,) robot headings (rad).
        groups: index arrays, one per circle (>= 3 photos each).
        iterations: IRLS iterations: the first half Huber, the rest drop photos beyond 3
            robust sigma (misregistered runs of a circle must not bend the lever arm).

    Returns:
        ``u`` (2,) the camera's lever arm in the robot frame (units of ``xy``), ``p``
        (n_circles, 2) the rotation axes, ``r`` (N,) residual lengths (NaN off circles).
    """
    idx = np.concatenate(groups)
    nc = len(groups)
    A = np.zeros((2 * len(idx), 2 * nc + 2))
    row = 0
    for c, g in enumerate(groups):
        for k in g:
            ch, sh = math.cos(h[k]), math.sin(h[k])
            A[row, 2 * c] = 1.0
            A[row + 1, 2 * c + 1] = 1.0
            A[row, -2:] = (ch, -sh)
            A[row + 1, -2:] = (sh, ch)
            row += 2
    b = xy[idx].reshape(-1)
    w = np.ones(len(idx))
    x = np.zeros(2 * nc + 2)
    for it in range(iterations):
        ww = np.repeat(np.sqrt(w), 2)
        x, *_ = np.linalg.lstsq(A * ww[:, None], b * ww, rcond=None)
        r = np.linalg.norm((A @ x - b).reshape(-1, 2), axis=1)
        sigma = max(1.4826 * float(np.median(r)), 1e-12)
        if it < iterations // 2:  # Huber first (convex), then reject beyond 3 sigma
            w = np.minimum(1.0, 1.5 * sigma / np.maximum(r, 1e-15))
        else:
            w = (r <= 3.0 * sigma).astype(float)
    res = np.full(len(xy), np.nan)
    res[idx] = r
    return x[-2:], x[:-2].reshape(nc, 2), res


def turn_in_place_circles(ph: list[Photo]) -> list[list[int]]:
    """Runs of consecutive photos (same round, by capture index) between which the robot's
    odometry position moved less than 1 cm: the robot turned in place, so the camera centres
    lie on a circle about one rotation axis.

    Args:
        ph: photos, (N,).

    Returns:
        Index lists into ``ph`` (>= 2 photos each), in capture order.
    """
    by_round: dict[int, list[int]] = {}
    for k, p in enumerate(ph):
        if p.odometry is not None:
            by_round.setdefault(p.round, []).append(k)
    runs: list[list[int]] = []
    for members in by_round.values():
        members.sort(key=lambda k: ph[k].index)
        cur = [members[0]]
        for a, b in itertools.pairwise(members):
            step = np.subtract(ph[b].odometry[:2], ph[a].odometry[:2])
            if np.linalg.norm(step) < 0.01:
                cur.append(b)
            else:
                if len(cur) >= 2:
                    runs.append(cur)
                cur = [b]
        if len(cur) >= 2:
            runs.append(cur)
    return runs


def _check_circle(
    xy: np.ndarray,
    h: np.ndarray,
    g: np.ndarray,
    min_photos: int,
    min_span_deg: float,
    max_rel_residual: float,
) -> dict:
    """Stats of one circle (photos ``g``) fitted on its own: photos, span, radius and
    residual (SfM units); ``rejected`` says why when it is not usable for the scale."""
    span = math.degrees(_heading_span(h[g]))
    d = {"photos": len(g), "span_deg": round(span, 1), "used": False}
    if len(g) < min_photos:
        d["rejected"] = f"fewer than {min_photos} photos"
    elif span < min_span_deg:
        d["rejected"] = f"heading span < {min_span_deg:g} deg"
    else:
        u_c, _, r_c = _fit_circles_lever_arm(xy, h, [g])
        radius_c = float(np.linalg.norm(u_c))
        d["radius_units"] = radius_c
        d["residual_median_units"] = float(np.nanmedian(r_c))
        if not d["residual_median_units"] <= max_rel_residual * radius_c:
            d["off_circle"] = True  # the map does not keep the photos on their circle
            d["rejected"] = (
                f"photos lie {d['residual_median_units'] / radius_c:.0%} of the radius "
                f"off the fitted circle (> {max_rel_residual:.0%})"
            )
    return d


def _reject_odd_radii(use: list[dict], max_spread: float) -> np.ndarray:
    """Which of the usable circles ``use`` keep: with three or more, those whose radius lies
    within ``max(3 robust sigma, max_spread)`` (relative) of the median; the others are
    marked ``rejected``."""
    radii = np.array([d["radius_units"] for d in use])
    keep = np.ones(len(use), bool)
    if len(use) >= 3:
        med = float(np.median(radii))
        sigma = 1.4826 * float(np.median(np.abs(radii - med)))
        keep = np.abs(radii - med) <= max(3 * sigma, max_spread * med)
        for d, k in zip(use, keep, strict=True):
            if not k:
                d["rejected"] = "radius disagrees with the other circles"
    return keep


def fit_scale_to_circles(
    xy: np.ndarray,
    h: np.ndarray,
    circles: list[list[int]],
    camera_offset_m: float,
    *,
    min_photos: int,
    min_span_deg: float = 90.0,
    max_spread: float = 0.03,
    max_rel_residual: float,
) -> tuple[float | None, np.ndarray, dict]:
    """Metric scale from the camera's known lever arm about the rotation axis.

    A robot turning in place moves its camera, mounted ``camera_offset_m`` from the rotation
    axis, on a circle of that radius, whatever the wheels slip. Per circle the model
    ``xy[k] = p + R(h[k]) @ u`` (axis ``p``, lever arm ``u`` in the robot frame, SfM units)
    is linear in ``p`` and ``u`` given the SfM headings; all usable circles share ``u``
    (one camera mount) and are fitted jointly (Huber IRLS), and the scale is
    ``camera_offset_m / |u|``. Circles with fewer than ``min_photos`` photos or spanning
    less than ``min_span_deg`` of heading are not used (the axis and the lever arm are not
    separable on a short arc). With three or more circles, circles whose own radius lies
    beyond ``max(3 robust sigma, max_spread)`` (relative) of the median are rejected, and so
    is a circle whose photos lie, in the median, farther than ``max_rel_residual`` of its
    radius from its own fitted circle (the camera's swing about the axis is lost in the
    map's noise: small photos of a far scene).

    Args:
        xy: (N, 2) camera centres in a heading-aligned horizontal frame (SfM units).
        h: (N,) robot headings (rad) from the model's camera orientations.
        circles: index lists into ``xy`` of turn-in-place runs (:func:`turn_in_place_circles`).
        camera_offset_m: distance of the camera centre from the rotation axis (m).
        min_photos: fewest photos for a circle to be used.
        min_span_deg: smallest heading span (deg) for a circle to be used.
        max_spread: relative radius deviation always tolerated between circles.
        max_rel_residual: largest median distance of a circle's photos from its fitted
            circle, as a share of its radius, for it to be used.

    Returns:
        ``scale`` (m per unit, ``None`` when no circle is usable), the lever arm ``u``
        (2,) in SfM units, and stats (per circle: photos, span, radius, scale, used).
    """
    info: list[dict] = []
    usable: list[np.ndarray] = []
    for g in circles:
        g = np.asarray(g)
        d = _check_circle(xy, h, g, min_photos, min_span_deg, max_rel_residual)
        if "radius_units" in d and "rejected" not in d:
            usable.append(g)
        info.append(d)
    stats: dict = {"circles": info}
    if not usable:
        return None, np.zeros(2), stats
    use = [d for d in info if "radius_units" in d and "rejected" not in d]
    keep = _reject_odd_radii(use, max_spread)
    groups = [g for g, k in zip(usable, keep, strict=True) if k]
    u, _, r = _fit_circles_lever_arm(xy, h, groups)
    radius = float(np.linalg.norm(u))
    if not radius > 0:
        return None, u, stats
    scale = camera_offset_m / radius
    for d, k in zip(use, keep, strict=True):
        d["used"] = bool(k)
        d["scale"] = camera_offset_m / d["radius_units"]
    stats.update(
        {
            "circles_used": len(groups),
            "circle_photos_used": int(sum(len(g) for g in groups)),
            "circle_residual_median_m": float(np.nanmedian(r)) * scale,
            "circle_scales_spread": float(np.ptp([d["scale"] for d in use if d["used"]])) / scale,
        }
    )
    return scale, u, stats


def _camera_geometry(rec: pycolmap.Reconstruction, names: list[str]):
    by_name = {rec.image(i).name: rec.image(i) for i in rec.reg_image_ids()}
    C, U, V = [], [], []
    for n in names:
        im = by_name[n]
        R = im.cam_from_world().rotation.matrix()
        C.append(im.projection_center())
        U.append(-R[1])
        V.append(R[2])
    return np.array(C), np.array(U), np.array(V)


def robot_frame_transform(
    rec: pycolmap.Reconstruction,
    photos: list[Photo],
    *,
    camera_yaw_deg: float,
    use_compass: bool,
    min_odometry_pairs: int,
    known_distance: tuple[str, str, float] | None = None,
    previous: pycolmap.Reconstruction | None = None,
    camera_offset_m: float | None,
    min_circle_photos: int,
    max_circle_residual: float,
) -> Alignment:
    """The similarity from the model's frame to the robot frame (see module docstring).

    Args:
        rec: the SfM model (any frame).
        photos: the photos (odometry, compass) of the set; unregistered ones are ignored.
        camera_yaw_deg: yaw of the camera relative to the robot's forward axis.
        use_compass: heading from the compass (else odometry theta, else the first photo).
        min_odometry_pairs: consecutive photo pairs needed for the odometry scale fit.
        known_distance: ``(name_a, name_b, metres)`` for photo sets without odometry.
        previous: round r-1's aligned model: x, y anchored to its shared photos (and scale
            taken from it when this set has too little odometry).
        camera_offset_m: the camera centre's known distance (m) from the robot's rotation
            axis: metric scale from circles of photos turned in place
            (:func:`fit_scale_to_circles`), odometry as fallback and cross-check; None: no
            lever-arm scale.
        min_circle_photos: fewest photos of a turn-in-place circle used for the scale.
        max_circle_residual: largest median residual of a circle's photos from its fitted
            circle, as a share of its radius, for it to count in the scale.

    Returns:
        The alignment.
    """
    reg = {rec.image(i).name for i in rec.reg_image_ids()}
    ph = [p for p in photos if p.name in reg]
    if len(ph) < 2:
        raise ValueError("need at least 2 registered photos to align the model")
    C, U, V = _camera_geometry(rec, [p.name for p in ph])
    prev_c = {}
    if previous is not None:
        prev_c = {
            previous.image(i).name: previous.image(i).projection_center()
            for i in previous.reg_image_ids()
        }
    return fit_robot_frame(
        ph,
        C,
        U,
        V,
        camera_yaw_deg=camera_yaw_deg,
        use_compass=use_compass,
        min_odometry_pairs=min_odometry_pairs,
        known_distance=known_distance,
        previous_centers=prev_c,
        camera_offset_m=camera_offset_m,
        min_circle_photos=min_circle_photos,
        max_circle_residual=max_circle_residual,
    )


def fit_robot_frame(
    ph: list[Photo],
    C: np.ndarray,
    U: np.ndarray,
    V: np.ndarray,
    *,
    camera_yaw_deg: float,
    use_compass: bool,
    min_odometry_pairs: int,
    known_distance: tuple[str, str, float] | None = None,
    previous_centers: dict[str, np.ndarray] | None = None,
    camera_offset_m: float | None,
    min_circle_photos: int,
    max_circle_residual: float,
) -> Alignment:
    """The robot-frame similarity from camera geometry arrays (core of
    :func:`robot_frame_transform`).

    Args:
        ph: the registered photos, (N,).
        C: (N, 3) camera centres, model frame.
        U: (N, 3) camera up vectors (-y axis of the OpenCV camera), model frame.
        V: (N, 3) viewing directions (+z axis of the camera), model frame.
        camera_yaw_deg, use_compass, min_odometry_pairs, known_distance: see
            :func:`robot_frame_transform`.
        previous_centers: photo name -> (3,) centre in the previous round's robot frame.
        camera_offset_m: known distance (m) of the camera centre from the rotation axis;
            when set, the scale comes from turn-in-place circles (odometry is the fallback
            and a cross-check, both in ``stats``).
        min_circle_photos: fewest photos of a circle used for the lever-arm scale.
        max_circle_residual: see :func:`robot_frame_transform`.

    Returns:
        The alignment.
    """
    names = [p.name for p in ph]
    stats: dict = {}
    prev_c = previous_centers or {}

    # 1. plane
    R1, psi = _level(C, U, V, camera_yaw_deg, stats)

    # 2. heading
    yaw, heading_source = _fit_heading(ph, psi, use_compass, stats)
    Rz = _rot_z(yaw)
    R = Rz @ R1
    C2 = C @ R.T
    h = _wrap(psi + yaw)  # robot headings in the robot frame

    # 3. scale
    idx = {nm: k for k, nm in enumerate(names)}
    est = _odometry_scale(_odometry_pairs(ph, idx, C2, h), min_odometry_pairs, stats)
    if camera_offset_m is not None:
        est.circles, est.lever_arm = _circle_scale(
            ph, C2, h, camera_offset_m, min_circle_photos, max_circle_residual, est.odometry, stats
        )
    scale, scale_source, offset = _choose_scale(est, known_distance, idx, C2, bool(prev_c))

    # 4. translation
    scale, scale_source, t, C3 = _translation(ph, C2, h, scale, scale_source, offset, prev_c, stats)
    z_res = C3[:, 2] + t[2]
    stats["plane_rms_m" if scale_source != "none" else "plane_rms_units"] = float(
        np.sqrt(np.mean(z_res**2))
    )
    return Alignment(scale, R, t, scale_source, heading_source, offset, stats)


def _level(
    C: np.ndarray, U: np.ndarray, V: np.ndarray, camera_yaw_deg: float, stats: dict
) -> tuple[np.ndarray, np.ndarray]:
    """Step 1: the rotation ``R1`` taking the camera centres' plane to z = 0 (plane stats
    into ``stats``) and the robot headings ``psi`` (N,) (rad) in the levelled model frame."""
    n, pstats = fit_plane_normal(C, U)
    stats.update(pstats)
    R1 = _rot_to_z(n)
    V1 = V @ R1.T
    cam_yaw = math.radians(camera_yaw_deg)
    psi = np.arctan2(V1[:, 1], V1[:, 0]) - cam_yaw  # robot headings, model frame
    return R1, psi


def _fit_heading(
    ph: list[Photo], psi: np.ndarray, use_compass: bool, stats: dict
) -> tuple[float, str]:
    """The yaw (rad) turning model headings ``psi`` onto the compass (else odometry theta,
    else the first photo's heading to 0), and its source; compass residuals into ``stats``."""
    compass = np.array([np.nan if p.compass_deg is None else p.compass_deg for p in ph])
    odo_theta = np.array([np.nan if p.odometry is None else p.odometry[2] for p in ph])
    has_c = ~np.isnan(compass)
    has_o = ~np.isnan(odo_theta)
    if use_compass and has_c.sum() >= 2:
        yaw = robust_circular_mean(_wrap(np.radians(compass[has_c]) - psi[has_c]))
        resid = _wrap(np.radians(compass[has_c]) - psi[has_c] - yaw)
        stats["compass_residual_median_deg"] = float(np.degrees(np.median(np.abs(resid))))
        return yaw, "compass"
    if has_o.sum() >= 2:
        return robust_circular_mean(_wrap(odo_theta[has_o] - psi[has_o])), "odometry"
    return -float(psi[0]), "first_photo"


@dataclass
class _ScaleEstimates:
    """The metric scale estimates of step 3 (:func:`fit_robot_frame`) before one is chosen.

    Attributes:
        pairs: consecutive photo pairs with odometry; ``moving``: those driving > 5 cm.
        odometry, odometry_offset: scale and camera offset from odometry, or None.
        circles, lever_arm: scale from the turn-in-place circles and the lever arm ``u``
            (SfM units), or None.
    """

    pairs: int
    moving: int
    odometry: float | None = None
    odometry_offset: tuple[float, float] | None = None
    circles: float | None = None
    lever_arm: np.ndarray | None = None


def _odometry_pairs(
    ph: list[Photo], idx: dict[str, int], C2: np.ndarray, h: np.ndarray
) -> list[tuple]:
    """Consecutive photo pairs of each round with odometry: (SfM camera displacement (2,),
    heading i, heading j, odometry displacement (2,))."""
    rows = []
    by_round: dict[int, list[Photo]] = {}
    for p in ph:
        if p.odometry is not None:
            by_round.setdefault(p.round, []).append(p)
    for members in by_round.values():
        members.sort(key=lambda p: p.index)
        for a, b in itertools.pairwise(members):
            i, j = idx[a.name], idx[b.name]
            dp = np.subtract(b.odometry[:2], a.odometry[:2])
            rows.append((C2[j, :2] - C2[i, :2], h[i], h[j], dp))
    return rows


def _odometry_scale(rows: list[tuple], min_odometry_pairs: int, stats: dict) -> _ScaleEstimates:
    """The odometry scale fit on the photo pairs ``rows`` when there are enough (stats into
    ``stats``)."""
    moving = sum(np.linalg.norm(r[3]) > 0.05 for r in rows)
    est = _ScaleEstimates(pairs=len(rows), moving=moving)
    if len(rows) >= min_odometry_pairs and moving >= 2:
        dc, hi, hj, dp = (np.array(x) for x in zip(*rows, strict=True))
        est.odometry, o, ostats = fit_scale_to_odometry(dc, hi, hj, dp)
        stats.update(ostats)
        stats["scale_odometry"] = est.odometry
        est.odometry_offset = (float(o[0]), float(o[1]))
    return est


def _circle_scale(
    ph: list[Photo],
    C2: np.ndarray,
    h: np.ndarray,
    camera_offset_m: float,
    min_circle_photos: int,
    max_circle_residual: float,
    odo_scale: float | None,
    stats: dict,
) -> tuple[float | None, np.ndarray]:
    """The lever-arm scale (None: no usable circle) and lever arm ``u`` (SfM units) from the
    turn-in-place circles (stats into ``stats``); warns when no circle is usable or the
    odometry scale ``odo_scale`` disagrees by more than 5 %."""
    circle_scale, u, cstats = fit_scale_to_circles(
        C2[:, :2],
        h,
        turn_in_place_circles(ph),
        camera_offset_m,
        min_photos=min_circle_photos,
        max_rel_residual=max_circle_residual,
    )
    stats.update(cstats)
    stats["scale_circles"] = circle_scale
    if circle_scale is None:
        why = sorted({c.get("rejected", "") for c in cstats["circles"]} - {""})
        log.warning(
            "sfm.camera_offset_m is set but no circle of photos turned in place is usable "
            "for the scale (needs >= %d registered photos over >= 90 deg of heading, "
            "within sfm.max_circle_residual = %.0f %% of the radius of its fitted circle; "
            "seen: %s): metric scale from %s instead",
            min_circle_photos,
            100 * max_circle_residual,
            "; ".join(why) or "no turn-in-place circle",
            "odometry" if odo_scale else "no source",
        )
    elif odo_scale:
        diff = odo_scale / circle_scale - 1.0
        stats["scale_odometry_vs_circles"] = diff
        if abs(diff) > 0.05:
            log.warning(
                "metric scale: odometry drive distances give %.1f %% %s than the camera "
                "lever arm (sfm.camera_offset_m = %.3f m); using the lever arm. Check "
                "the mount measurement or the wheel odometry.",
                abs(diff) * 100,
                "more" if diff > 0 else "less",
                camera_offset_m,
            )
    return circle_scale, u


def _choose_scale(
    est: _ScaleEstimates,
    known_distance: tuple[str, str, float] | None,
    idx: dict[str, int],
    C2: np.ndarray,
    has_previous: bool,
) -> tuple[float, str, tuple[float, float] | None]:
    """Scale, its source and the camera offset (m) by priority: known distance, lever arm,
    odometry, previous model (scale set in the translation step), none (scale 1)."""
    if known_distance is not None:
        a, b, dist = known_distance
        if a not in idx or b not in idx:
            raise ValueError(
                f"sfm.known_distance names photos {a!r}, {b!r}; not both registered "
                f"(registered: {len(C2)} photos)"
            )
        return dist / float(np.linalg.norm(C2[idx[a]] - C2[idx[b]])), "known_distance", None
    if est.circles is not None:
        u = est.lever_arm
        offset = (float(est.circles * u[0]), float(est.circles * u[1]))
        return est.circles, "camera_lever_arm", offset
    if est.odometry is not None:
        if not est.odometry > 0:
            raise ValueError(
                f"odometry scale fit gave {est.odometry:.3g}: odometry and SfM disagree; check "
                "the capture log's odometry"
            )
        return est.odometry, "odometry", est.odometry_offset
    if has_previous:
        return 1.0, "previous_model", None
    log.warning(
        "no metric scale: %d consecutive odometry pairs (%d moving), no "
        "sfm.known_distance or sfm.camera_offset_m; the model keeps SfM units (scale 1)",
        est.pairs,
        est.moving,
    )
    return 1.0, "none", None


def _translation(
    ph: list[Photo],
    C2: np.ndarray,
    h: np.ndarray,
    scale: float,
    scale_source: str,
    offset: tuple[float, float] | None,
    prev_c: dict[str, np.ndarray],
    stats: dict,
) -> tuple[float, str, np.ndarray, np.ndarray]:
    """Step 4: the translation (median height to 0; x, y anchored to the previous model's
    shared photos, else round 0's first odometry, else the first photo).

    Returns:
        The scale and its source (the previous model's when it gives the scale), the
        translation ``t`` (3,) and the scaled centres ``C3`` (N, 3).
    """
    names = [p.name for p in ph]
    C3 = scale * C2
    t = np.zeros(3)
    t[2] = -float(np.median(C3[:, 2]))
    shared = [k for k, nm in enumerate(names) if nm in prev_c]
    if len(shared) >= 2:
        P = np.array([prev_c[names[k]] for k in shared])
        if scale_source in ("previous_model", "none"):
            # scale from the spread of shared centres about their medians
            d_new = np.linalg.norm(C2[shared] - np.median(C2[shared], 0), axis=1)
            d_old = np.linalg.norm(P - np.median(P, 0), axis=1)
            if np.median(d_new) > 0:
                scale = float(np.median(d_old) / np.median(d_new))
                scale_source = "previous_model"
            C3 = scale * C2
            t[2] = -float(np.median(C3[:, 2]))
        t[:2] = np.median(P[:, :2] - C3[shared, :2], 0)
        stats["anchor"] = f"previous_model ({len(shared)} shared photos)"
    else:
        t[:2], stats["anchor"] = _anchor_without_previous(ph, C3, h, offset)
    return scale, scale_source, t, C3


def _anchor_without_previous(
    ph: list[Photo], C3: np.ndarray, h: np.ndarray, offset: tuple[float, float] | None
) -> tuple[np.ndarray, str]:
    """x, y translation putting round 0's first photo at its odometry (robot position, so
    less the camera offset), else the first photo at the origin; and how (``anchor``)."""
    r0 = [k for k, p in enumerate(ph) if p.odometry is not None and p.round == 0]
    if r0:
        k = min(r0, key=lambda k: ph[k].index)
        robot_xy = C3[k, :2]
        if offset is not None:
            robot_xy = robot_xy - _rot_z(h[k])[:2, :2] @ np.asarray(offset)
        return np.asarray(ph[k].odometry[:2]) - robot_xy, f"odometry of {ph[k].name}"
    return -C3[0, :2], f"first photo {ph[0].name} at the origin"


def align_to_robot_frame(rec: pycolmap.Reconstruction, alignment: Alignment) -> None:
    """Apply ``alignment`` to ``rec`` in place (images and points)."""
    rec.transform(alignment.sim3d())
