"""The frame of a person's photos (``robot: photos``): up from the photos themselves.

A person's photos have no floor plane, odometry or compass, and may be rolled 90 or 180
degrees (a phone held sideways, a gantry's second configuration), so the mean of the
cameras' image-up vectors says nothing about up (on the temple ring it is ~0). Instead
(:func:`estimate_up`):

1. **Up axis**: the direction most perpendicular to the changes of the cameras' optical
   axes and to the camera centres' offsets from their centroid: people (and gantries) hold
   cameras at one elevation (level, or looking down at an object all around it) and at
   similar heights. Each cue is a (3, 3) scatter matrix of unit directions normalized to
   trace 1; the axis is the eigenvector of the smallest eigenvalue of their sum.

   * Optical axes: their scatter about their mean when they share one elevation about a
     determined axis within ``MAX_COMMON_ELEVATION_DEG`` of level (a ring or arc of
     photos looking down at an object: a level-camera model would tilt up by the arc's
     mean look-down), else their scatter about level (a strip of photos of a facade, all
     facing one way).
   * Camera centres: the offsets from their centroid weighted by their length (coincident
     cameras add nothing). When only the optical axes determine an axis (the centres on a
     line: a street, stairs) the centres only break ties (weight ``TIE_BREAK``), so photos
     taken climbing stairs while looking around do not tilt the frame.

   A few rounds of Cauchy re-weighting (scale ``LEVEL_TOLERANCE_DEG``) keep photos shot
   steeply up or down, or from a ladder, from tilting it. No plane is assumed: a facade
   strip (centres on a line, axes one way) is determined by the two cues together. Not
   determined: photos facing one way climbing stairs (tilted by the slope), a short arc
   looking steeply down. Each cue's own axis, their angle and warnings go to report.json
   (``alignment.stats.up``); ``sfm.up_photo`` overrides the estimate, and so does the
   plane of a guided campaign's round-0 walk (photos taken standing at eye height, whose
   heights spread by centimetres where a person tilts the camera by degrees:
   :mod:`scenebot.sfm.person_check`).
2. **Sign**: from the image-up vectors when they are informative (their mean component
   along the axis at least ``IMAGE_UP_INFORMATIVE``: most photos upright, or most upside
   down), else the sign that makes the cameras look down on average (photos of things
   around and below eye level), with a warning when that mean is within two standard
   errors of level.

The frame: z up, z = 0 at the median camera height, origin below the cameras' centroid,
x along the first photo's viewing direction (levelled); metres from ``sfm.known_distance``,
else SfM units with the warning "scale unknown: lengths are in SfM units" (log and
report.json). The robot's frame (:mod:`scenebot.sfm.align`) is not used here.
"""

from __future__ import annotations

import logging
import math

import numpy as np
import pycolmap

from scenebot.sfm.align import Alignment, _camera_geometry, _rot_to_z, _rot_z
from scenebot.sfm.photos import Photo

log = logging.getLogger(__name__)

LEVEL_TOLERANCE_DEG = 10.0
"""Scale of the Cauchy re-weighting (deg from level): an optical axis or a camera offset
this far off the horizontal weighs half as much."""
IMAGE_UP_INFORMATIVE = 0.5
"""The image-up vectors decide the sign when their mean component along the up axis is at
least this (in absolute value; 1: all photos upright or all upside down; ~0: rolled 90
degrees either way, as on the temple ring)."""
CUE_DETERMINED = 0.05
"""A cue determines an up axis by itself when its second-smallest eigenvalue (of trace 1)
is at least this and at least 4 times its smallest (the directions span a plane)."""
MAX_COMMON_ELEVATION_DEG = 45.0
"""The optical axes count as sharing one elevation (not level) only when it lies within
this of level: people photograph what is around them, not mostly straight up or down (a
strip of photos of a facade would otherwise read as photos of the ground)."""
TIE_BREAK = 0.01
"""Weight of the camera-offsets cue when only the optical axes determine up (see
:func:`_tie_break_weight`)."""
SCALE_UNKNOWN = "scale unknown: lengths are in SfM units"
"""The warning (log and report.json) when no ``sfm.known_distance`` gives the scale."""


def _scatter(dirs: np.ndarray, w: np.ndarray) -> np.ndarray:
    """(3, 3) weighted scatter of unit directions ``dirs`` (N, 3), trace 1 (zeros if empty)."""
    tot = float(w.sum())
    if tot <= 0:
        return np.zeros((3, 3))
    return (dirs * (w / tot)[:, None]).T @ dirs


def _cue_axis(M: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
    """Smallest eigenvector of a cue's scatter, its eigenvalues (ascending) and whether the
    cue determines an axis by itself (:data:`CUE_DETERMINED`)."""
    lam, vec = np.linalg.eigh(M)
    determined = bool(lam[1] >= CUE_DETERMINED and lam[1] >= 4.0 * max(lam[0], 0.0))
    return vec[:, 0], lam, determined


def _axes_cue(views: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, str]:
    """The optical axes' cue: their scatter about their weighted mean (trace 1) when the
    axes share one elevation about a determined axis and that elevation is plausible
    (within :data:`MAX_COMMON_ELEVATION_DEG` of level: cameras looking down at an object
    all around it, a gantry), else their scatter about level (cameras held level).

    Returns:
        The scatter (3, 3), the centre the residuals are taken from (the mean axis, or
        zeros), and the model (``common_elevation`` or ``level``).
    """
    mean = (views * (w / w.sum())[:, None]).sum(0)
    cone = _scatter(views - mean, w)
    cone /= max(float(np.trace(cone)), 1e-300)
    axis, _, determined = _cue_axis(cone)
    if determined and abs(float(mean @ axis)) <= math.sin(math.radians(MAX_COMMON_ELEVATION_DEG)):
        return cone, mean, "common_elevation"
    return _scatter(views, w), np.zeros(3), "level"


def _tie_break_weight(A: np.ndarray, D: np.ndarray) -> float:
    """Weight of the camera-offsets cue ``D`` beside the optical-axes cue ``A``: 1, or
    :data:`TIE_BREAK` when the axes determine up by themselves and the offsets do not (a
    line of cameras: stairs, a street), which then only break ties."""
    if _cue_axis(A)[2] and not _cue_axis(D)[2]:
        return TIE_BREAK
    return 1.0


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Angle (deg) between the axes ``a`` and ``b`` (unit, sign ignored)."""
    return math.degrees(math.acos(min(1.0, abs(float(a @ b)))))


def estimate_up(
    views: np.ndarray, centers: np.ndarray, ups: np.ndarray, iterations: int = 5
) -> tuple[np.ndarray, dict]:
    """The up direction of a photo set from its cameras (see the module docstring).

    Args:
        views: (N, 3) optical axes (unit, +z of the camera), model frame.
        centers: (N, 3) camera centres, model frame.
        ups: (N, 3) image-up vectors (unit, -y of the camera), model frame.
        iterations: rounds of Cauchy re-weighting.

    Returns:
        ``up`` (3,) unit vector, and stats: per axis cue (``optical_axes``,
        ``camera_centres``) whether it determines an axis alone, its own axis's angle to
        ``up`` (deg) and the rms angle of its directions off the horizontal (deg), for the
        optical axes also their ``model`` (``common_elevation`` or ``level``) and
        ``spread_deg`` about it; ``camera_centres_weight`` (1 or :data:`TIE_BREAK`);
        ``cues_angle_deg`` (between the two cues' own axes, when both determine one);
        ``eigenvalues`` of the combined scatter and ``weakly_determined``; the sign cues
        (``image_up_mean``, ``image_up_informative``, ``mean_view_elevation_deg``,
        ``sign_source``, ``sign_certain``, ``sign_cues_agree``); ``downweighted_photos``
        (indices of the photos whose optical axis weighs less than half).
    """
    views = np.asarray(views, float)
    offsets = np.asarray(centers, float) - np.asarray(centers, float).mean(0)
    length = np.linalg.norm(offsets, axis=1)
    moved = length > 1e-12 * max(float(length.max(initial=0.0)), 1e-300)
    odirs = offsets[moved] / length[moved, None]
    s = math.sin(math.radians(LEVEL_TOLERANCE_DEG))
    wv, wo = np.ones(len(views)), length[moved]
    for k in range(iterations + 1):
        (A, centre, model), D = _axes_cue(views, wv), _scatter(odirs, wo)
        lam, vec = np.linalg.eigh(A + _tie_break_weight(A, D) * D)
        up = vec[:, 0]
        if k < iterations:
            wv = 1.0 / (1.0 + ((views - centre) @ up / s) ** 2)
            wo = length[moved] / (1.0 + (odirs @ up / s) ** 2)
    stats: dict = {
        "eigenvalues": [float(x) for x in lam],
        "weakly_determined": bool(lam[1] < 3.0 * max(lam[0], 1e-12)),
        "camera_centres_weight": _tie_break_weight(A, D),
    }
    cue_axes = {}
    for name, M, dirs in (("optical_axes", A, views), ("camera_centres", D, odirs)):
        axis, _, determined = _cue_axis(M)
        elev = np.degrees(np.arcsin(np.clip(dirs @ up, -1, 1))) if len(dirs) else np.zeros(1)
        stats[name] = {
            "determines_axis": determined,
            "axis_angle_to_up_deg": _angle_deg(axis, up) if determined else None,
            "rms_off_horizontal_deg": float(np.sqrt(np.mean(elev**2))),
        }
        if determined:
            cue_axes[name] = axis
    stats["optical_axes"]["model"] = model
    stats["optical_axes"]["spread_deg"] = float(
        np.degrees(np.sqrt(np.mean(((views - centre) @ up) ** 2)))
    )
    stats["cues_angle_deg"] = _angle_deg(*cue_axes.values()) if len(cue_axes) == 2 else None
    down = np.flatnonzero(wv < 0.5)
    stats["downweighted_photos"] = [int(i) for i in down]
    up, sign_stats = _orient(up, views, ups)
    stats.update(sign_stats)
    return up, stats


def _orient(up: np.ndarray, views: np.ndarray, ups: np.ndarray) -> tuple[np.ndarray, dict]:
    """The sign of the axis ``up``: the image-up vectors' when informative, else the one
    that makes the cameras look down on average; and the sign cues' stats."""
    m_up = float(np.mean(ups @ up))
    informative = abs(m_up) >= IMAGE_UP_INFORMATIVE
    m_view = float(np.mean(views @ up))
    if informative:
        sign, source = (1.0 if m_up > 0 else -1.0), "image_up"
    else:
        sign, source = (1.0 if m_view <= 0 else -1.0), "cameras_look_down"
    elev = np.degrees(np.arcsin(np.clip(sign * (views @ up), -1, 1)))
    # the look-down sign is a guess when the mean elevation is within 2 standard errors of 0
    sure = informative or abs(elev.mean()) > 2.0 * elev.std() / math.sqrt(len(elev))
    stats = {
        "image_up_mean": sign * m_up,
        "image_up_informative": informative,
        "mean_view_elevation_deg": float(elev.mean()),
        "sign_source": source,
        "sign_certain": bool(sure),
        # the image-up vectors lean up and the cameras look down (None: one cue only)
        "sign_cues_agree": bool(elev.mean() <= 0) if informative else None,
    }
    return sign * up, stats


def side_direction(up: np.ndarray, view: np.ndarray, side: str) -> np.ndarray:
    """The direction (3,) of a photo's ``side`` (top, bottom, left, right) from its camera's
    image-up vector ``up`` (-y) and optical axis ``view`` (+z), both (3,) unit."""
    right = np.cross(-up, view)  # +x of the camera: x = y cross z
    return {"top": up, "bottom": -up, "left": -right, "right": right}[side]


def person_frame_transform(
    rec: pycolmap.Reconstruction,
    photos: list[Photo],
    *,
    known_distance: tuple[str, str, float] | None,
    up_photo: tuple[str, str] | None,
    standing_up: np.ndarray | None = None,
) -> Alignment:
    """The similarity from the model's frame to a person's frame (module docstring).

    Args:
        rec: the SfM model (any frame).
        photos: the photo set, in capture (name) order; unregistered ones are ignored.
        known_distance: ``(name_a, name_b, metres)`` between two camera centres, or None.
        up_photo: ``(name, side)``: the side of that photo that points up (overrides the
            estimate), or None.
        standing_up: (3,) the normal (model frame) of the plane of the photos taken
            standing at eye height (:mod:`scenebot.sfm.person_check`), or None: up, unless
            ``up_photo`` is set (its sign: the estimate's).

    Returns:
        The alignment (:func:`fit_person_frame`).
    """
    reg = {rec.image(i).name for i in rec.reg_image_ids()}
    names = [p.name for p in photos if p.name in reg]
    if len(names) < 2:
        raise ValueError("need at least 2 registered photos to align the model")
    C, U, V = _camera_geometry(rec, names)
    return fit_person_frame(
        names, C, U, V, known_distance=known_distance, up_photo=up_photo, standing_up=standing_up
    )


def fit_person_frame(
    names: list[str],
    C: np.ndarray,
    U: np.ndarray,
    V: np.ndarray,
    *,
    known_distance: tuple[str, str, float] | None,
    up_photo: tuple[str, str] | None,
    standing_up: np.ndarray | None = None,
) -> Alignment:
    """The person's frame from camera geometry arrays (core of
    :func:`person_frame_transform`).

    Args:
        names: the registered photos, (N,), in capture order (the first sets the heading).
        C: (N, 3) camera centres; U: (N, 3) image-up vectors (-y of the camera); V: (N, 3)
            optical axes (+z); model frame.
        known_distance, up_photo, standing_up: see :func:`person_frame_transform`.

    Returns:
        The alignment; ``stats["up"]`` says which cues decided up and how well they agree
        (:func:`estimate_up`), ``stats["warnings"]`` what the user should know.

    Raises:
        ValueError: a known distance or up photo that names a photo not registered.
    """
    warnings: list[str] = []
    up, up_stats = estimate_up(V, C, U)
    if up_photo is not None:
        if up_photo[0] not in names:
            raise ValueError(
                f"sfm.up_photo names {up_photo[0]!r}, which is not a registered photo of the "
                "map: name a photo of the folder that registered (report.json lists the "
                "dropped ones)"
            )
        k = names.index(up_photo[0])
        hint = side_direction(U[k], V[k], up_photo[1])
        up_stats = {
            "source": f"sfm.up_photo ({up_photo[1]} of {up_photo[0]})",
            "estimate_angle_deg": math.degrees(math.acos(np.clip(float(hint @ up), -1, 1))),
            "estimate": up_stats,
        }
        up = hint
    elif standing_up is not None:
        # the standing photos' camera heights spread a few cm over metres: their plane
        # levels the frame far better than optical axes that a person tilts by degrees
        n = np.asarray(standing_up, float) / np.linalg.norm(standing_up)
        n = n if float(n @ up) >= 0 else -n
        up_stats["downweighted_photos"] = [names[k] for k in up_stats["downweighted_photos"]]
        up_stats = {
            "source": "plane of the photos taken standing (sfm.person_height_std_m)",
            "estimate_angle_deg": math.degrees(math.acos(np.clip(float(n @ up), -1, 1))),
            "estimate": up_stats,
        }
        up = n
    else:
        up_stats["source"] = "photos"
        up_stats["downweighted_photos"] = [names[k] for k in up_stats["downweighted_photos"]]
        warnings += _up_warnings(up_stats)
    R1 = _rot_to_z(up)
    R = _rot_z(-_first_heading(V[0] @ R1.T, U[0] @ R1.T)) @ R1
    C2 = C @ R.T
    scale, scale_source = _scale(known_distance, names, C2)
    if scale_source == "none":
        warnings.append(SCALE_UNKNOWN)
        log.warning(
            "%s: set sfm.known_distance (two photos' file names and the distance between "
            "their camera centres, m) for a metric map",
            SCALE_UNKNOWN,
        )
    C3 = scale * C2
    t = np.zeros(3)
    t[:2] = -C3[:, :2].mean(0)
    t[2] = -float(np.median(C3[:, 2]))
    stats = {
        "frame": "person",
        "up": up_stats,
        "anchor": "origin below the cameras' centroid, z = 0 at their median height",
        "heading": f"x along the view of the first photo, {names[0]}",
        "plane_rms_m" if scale_source != "none" else "plane_rms_units": float(
            np.sqrt(np.mean((C3[:, 2] + t[2]) ** 2))
        ),
        "warnings": warnings,
    }
    return Alignment(scale, R, t, scale_source, "first_photo", None, stats)


def _up_warnings(up_stats: dict) -> list[str]:
    """Warnings (also logged) when the estimated up is weakly determined or its cues
    disagree."""
    out = []
    if up_stats["weakly_determined"]:
        out.append(
            "up is weakly determined by the photos (optical axes and camera positions "
            "leave two directions alike): check map.png and set sfm.up_photo if it is wrong"
        )
    if not up_stats["sign_certain"]:
        out.append(
            "which way is up is uncertain: the photos are rolled (their image-up vectors "
            "do not agree) and the cameras look neither up nor down on average; check "
            "map.png and set sfm.up_photo if the map is upside down"
        )
    if up_stats["sign_cues_agree"] is False:
        out.append(
            "the photos' image-up vectors say up is where the cameras look up to on average "
            f"({up_stats['mean_view_elevation_deg']:.0f} deg); their image-up decided: check "
            "map.png and set sfm.up_photo if the map is upside down (photos stored rotated, "
            "with an EXIF orientation, look upside down or sideways to SfM)"
        )
    angle = up_stats["cues_angle_deg"]
    if angle is not None and angle > 2 * LEVEL_TOLERANCE_DEG:
        out.append(
            f"the optical axes and the camera positions disagree on up by {angle:.0f} deg "
            "(photos looking steeply down, or taken on a slope or stairs): check map.png and "
            "set sfm.up_photo if it is wrong"
        )
    for w in out:
        log.warning(w)
    return out


def _first_heading(view: np.ndarray, img_up: np.ndarray) -> float:
    """Heading (rad) of the first photo in the levelled frame: its optical axis, or its
    image-up vector when it looks nearly straight up or down."""
    d = view if math.hypot(view[0], view[1]) > 0.1 else img_up
    return math.atan2(d[1], d[0])


def _scale(
    known_distance: tuple[str, str, float] | None, names: list[str], C2: np.ndarray
) -> tuple[float, str]:
    """Metres per SfM unit and its source (``known_distance`` or ``none``: 1)."""
    if known_distance is None:
        return 1.0, "none"
    a, b, dist = known_distance
    idx = {n: k for k, n in enumerate(names)}
    if a not in idx or b not in idx:
        raise ValueError(
            f"sfm.known_distance names photos {a!r}, {b!r}; not both registered "
            f"(registered: {len(names)} photos): name two photos that registered"
        )
    d = float(np.linalg.norm(C2[idx[a]] - C2[idx[b]]))
    if not d > 0:
        raise ValueError(f"sfm.known_distance: photos {a!r} and {b!r} share a camera centre")
    return dist / d, "known_distance"
