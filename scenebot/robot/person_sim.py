"""The simulated person (``robot: person-sim``): a person with a camera in a simulated world.

For tests and evaluation of guided campaigns: round 0 is a walk along the room's walls,
photos at even spacing facing into the room (:func:`perimeter_walk`); every later round the
person walks to each shot of the previous round's guide and takes it with a person's error
(:meth:`SimPerson.shoot`): about ``person_sim.position_std_m`` off where the shot is,
``heading_std_deg`` off its heading, at a height it can hold the camera (its own eye height,
drawn once per campaign from ``eye_height_m``, crouched down to ``lowest_m`` or raised by
``reach_up_m``), tilted as asked plus ``pitch_std_deg``, holding the camera out up to
``reach_m`` from where it can stand. Shots it cannot reach (outside the room, inside
furniture) it skips.

The person may use the simulated world's geometry (where it can stand) and where it truly
stood for its own earlier photos (to read the guide's map: :func:`map_to_world`); nothing
here is read by a stage to decide anything. Its photos carry the simulator's truth for the
evaluation, in the records of :mod:`scenebot.capturelog` (``truth``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scenebot.geometry import Intrinsics, orientation_rotation, similarity_fit
from scenebot.jpeg import store_photo, write_jpeg
from scenebot.robot.person_config import PersonSimConfig
from scenebot.scene.mesh import SceneMesh
from scenebot.sim.obstacles import ObstacleMap

BODY_BAND_M = (0.1, 1.5)
"""Heights (m above the floor) of the geometry that keeps a person from standing there."""
WALL_BAND = (0.8, 0.9)
"""Heights, as fractions of the room's height, of the geometry the walk follows: the walls
(furniture stays below)."""
STEP_ASIDE_M = 1.5
"""A spot of the walk inside furniture moves to the nearest spot the person fits, at most
this far (m); else the photo is not taken."""
MAP_RES_M = 0.01
"""Cell size (m) of the person's map of where it can stand."""
RECOGNISE_M = 0.25
"""A photo of the map agrees with the person's reading when it lies within this (m) of where
the person truly took it."""
RANSAC_TRIES = 300
"""Minimal sets of three photos tried when reading the map."""
TANGENT_SPAN_M = 1.0
"""The walk's direction at a photo is taken over this much of it (m)."""
FOOT_RES_M = 0.05
"""Cell size (m) of the grid the person finds its way between rooms on."""


@dataclass
class ShotPose:
    """A camera pose in the world: centre (m), heading (rad, counter-clockwise from +x),
    tilt (rad, up positive) and roll (rad)."""

    center: np.ndarray
    heading: float
    pitch: float
    roll: float = 0.0

    def rotation(self) -> np.ndarray:
        """(3, 3) cam_from_world rotation (x right, y down, z forward)."""
        return orientation_rotation(self.heading, self.pitch, self.roll)


@dataclass
class Shot:
    """What the person did for one shot: the pose aimed at (world), the pose truly taken
    (None when skipped) and why it was skipped."""

    aimed: ShotPose
    taken: ShotPose | None = None
    skipped: str | None = None
    extra: dict = field(default_factory=dict)


class SimPerson:
    """A person with a camera in ``scene``.

    Args:
        scene: the simulated world.
        cfg: the person's settings.
        camera: the camera's settings (``sim.camera``: image size, field of view, noise,
            JPEG quality, sensor width).
        seed: seed of the person's eye height and errors (the campaign's ``seed`` with the
            round: every round draws its own errors).
        eye_seed: seed of the eye height alone (the campaign's: the same person every round).
    """

    def __init__(self, scene: SceneMesh, cfg: PersonSimConfig, camera, seed, eye_seed: int):
        from scenebot.sim.renderer import Renderer

        self.scene = scene
        self.cfg = cfg
        self.camera = camera
        self.rng = np.random.default_rng(seed)
        # the phone's sensors draw from their own stream: the person's other errors stay the
        # same with or without them
        self.sensor_rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(1)[0])
        self.motion_rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(2)[1])
        lo, hi = cfg.eye_height_m
        self.eye_height_m = float(np.random.default_rng([eye_seed, 7]).uniform(lo, hi))
        fz = scene.floor_z
        self.map = ObstacleMap.build(scene, fz + BODY_BAND_M[0], fz + BODY_BAND_M[1], MAP_RES_M)
        top = float(scene.bounds[1][2]) - fz
        self.walls = ObstacleMap.build(  # every room's walls (lintels close the doorways)
            scene, fz + WALL_BAND[0] * top, fz + WALL_BAND[1] * top, MAP_RES_M, every_region=True
        )
        self.intrinsics = Intrinsics.from_hfov(camera.width, camera.height, camera.hfov_deg)
        self._renderer = None
        self._renderer_cls = Renderer

    # ------------------------------------------------------------------ where it can stand
    def can_stand(self, xy) -> bool:
        """Whether the person fits at world ``xy``: inside the room (the free region the map
        keeps; outside the walls and inside solids are occupied) and at least
        ``clearance_m`` from furniture and walls."""
        xy = np.asarray(xy, float)
        h, w = self.map.occupied.shape
        c = np.round((xy - self.map.origin) / self.map.res).astype(int)
        if not (0 <= c[0] < w and 0 <= c[1] < h):
            return False
        return bool(self.map.clearance[c[1], c[0]] >= self.cfg.clearance_m)

    def nearest_standable(self, xy, max_m: float = STEP_ASIDE_M) -> np.ndarray | None:
        """The spot nearest ``xy`` the person fits at (:meth:`can_stand`), within ``max_m``;
        None without one."""
        if self.can_stand(xy):
            return np.asarray(xy, float)
        r, c = self.map._cell(xy)
        k = round(max_m / self.map.res)
        h, w = self.map.occupied.shape
        r0, c0 = max(r - k, 0), max(c - k, 0)
        win = self.map.clearance[r0 : min(r + k + 1, h), c0 : min(c + k + 1, w)]
        rr, cc = np.nonzero(win >= self.cfg.clearance_m)
        if len(rr) == 0:
            return None
        spots = self.map.origin + np.column_stack([cc + c0, rr + r0]) * self.map.res
        d = np.linalg.norm(spots - np.asarray(xy, float), axis=1)  # from xy, not its cell
        j = int(np.argmin(d))
        return spots[j] if d[j] <= max_m else None

    def camera_height_range(self) -> tuple[float, float]:
        """Lowest and highest camera height (m, world z) the person can hold the camera at."""
        fz = self.scene.floor_z
        return fz + self.cfg.lowest_m, fz + self.eye_height_m + self.cfg.reach_up_m

    # ------------------------------------------------------------------------- shooting
    def shoot(self, aimed: ShotPose) -> Shot:
        """Walk to the shot ``aimed`` (world) and take it as a person does: stand where it
        fits nearest the shot (within ``reach_m``: the camera held out over a desk or a
        sofa), with the error of the settings around it; skipped, with the reason, when no
        such spot is near or the shot's spot lies inside or behind furniture from there."""
        cfg = self.cfg
        xy = np.asarray(aimed.center[:2], float)
        stand0 = self.nearest_standable(xy, cfg.reach_m)
        if stand0 is None:
            lo, hi = self.scene.bounds
            where = (
                "outside the room"
                if np.any(xy < lo[:2]) or np.any(xy > hi[:2])
                else "outside the room or in furniture: no spot the person fits (person_sim."
                f"clearance_m = {cfg.clearance_m} m) within person_sim.reach_m = "
                f"{cfg.reach_m} m of it"
            )
            return Shot(aimed, skipped=f"the spot ({xy[0]:.2f}, {xy[1]:.2f}) m is {where}")
        arm = xy - stand0  # the camera held out this far from where the person stands
        for _ in range(20):  # a person does not step into the furniture: stand elsewhere
            cam_xy = xy + self.rng.normal(0.0, cfg.position_std_m, 2)
            if self.can_stand(cam_xy - arm):
                break
        else:
            cam_xy = xy
        stand = cam_xy - arm
        lo, hi = self.camera_height_range()
        z = float(np.clip(aimed.center[2], lo, hi) + self.rng.normal(0.0, cfg.height_std_m))
        z = float(np.clip(z, lo, hi))
        if self._blocked(np.array([stand[0], stand[1], z]), np.array([cam_xy[0], cam_xy[1], z])):
            return Shot(
                aimed,
                skipped=f"the spot ({xy[0]:.2f}, {xy[1]:.2f}, {z:.2f}) m is inside or behind "
                f"furniture from where the person can stand ({stand[0]:.2f}, {stand[1]:.2f})",
            )
        pitch = aimed.pitch + math.radians(self.rng.normal(0.0, cfg.pitch_std_deg))
        taken = ShotPose(
            np.array([cam_xy[0], cam_xy[1], z]),
            aimed.heading + math.radians(self.rng.normal(0.0, cfg.heading_std_deg)),
            float(np.clip(pitch, -math.radians(89), math.radians(89))),
            math.radians(self.rng.normal(0.0, cfg.roll_std_deg)),
        )
        return Shot(aimed, taken, extra={"stood_at": [float(stand[0]), float(stand[1])]})

    def _blocked(self, a: np.ndarray, b: np.ndarray) -> bool:
        """Whether geometry lies between the points ``a`` and ``b`` (the person's arm)."""
        d = b - a
        n = float(np.linalg.norm(d))
        if n < 1e-6:
            return False
        hit = self.renderer().cast(a[None], (d / n)[None])
        return bool(hit["t"][0] < n)

    def renderer(self):
        """The simulator's renderer of the scene (made on first use)."""
        if self._renderer is None:
            cam = self.camera
            self._renderer = self._renderer_cls(
                self.scene, noise_sigma=cam.noise_sigma, antialias=cam.antialias
            )
        return self._renderer

    def take(self, pose: ShotPose, dest: Path) -> dict:
        """Render the photo of ``pose`` into ``dest`` (a JPEG with EXIF focal length, stored
        atomically and never over a file) and return its ``truth`` record (capture log)."""
        cam = self.camera
        R = pose.rotation()
        rgb = self.renderer().render(self.intrinsics, R, pose.center, self.rng)
        store_photo(
            Path(dest),
            lambda tmp: write_jpeg(
                tmp, rgb, self.intrinsics.fx, cam.sensor_width_mm, cam.jpeg_quality,
                model="person-sim",
            ),
        )  # fmt: skip
        return truth_record(pose)


def orientation_record(person: SimPerson, pose: ShotPose) -> dict:
    """The fields the person's phone adds to a photo's record: ``orientation``, the compass
    heading with ``person_sim.compass_std_deg`` of error, the pitch and roll from its
    accelerometer with ``gravity_std_deg``; none for a phone without them (``compass_std_deg``
    null). Degrees, the heading counter-clockwise like the map's."""
    cfg = person.cfg
    if cfg.compass_std_deg is None:
        return {}
    rng = person.sensor_rng
    return {
        "orientation": {
            "heading_deg": math.degrees(pose.heading) + float(rng.normal(0, cfg.compass_std_deg)),
            "pitch_deg": math.degrees(pose.pitch) + float(rng.normal(0, cfg.gravity_std_deg)),
            "roll_deg": math.degrees(pose.roll) + float(rng.normal(0, cfg.gravity_std_deg)),
        }
    }


class PhoneMotion:
    """The phone's own tracking of its motion (visual-inertial odometry, as ARKit and ARCore
    give it): each photo's camera pose in the session's frame, which is level (gravity) with
    an arbitrary heading and its origin where the session began. One session per round (the
    person opens the capture app again): poses of two sessions are not comparable. It drifts
    as a person walks, by about ``person_sim.motion_drift`` of the distance walked: each
    step is tracked with a scale error (drawn once per session, that standard deviation),
    turned by the tracked heading's error (a random walk of that many radians per square
    root metre) and with a random error of that fraction of its length (per axis, half that
    vertically); ``walked_m`` is the length of the session's track so far."""

    def __init__(self, drift: float, rng: np.random.Generator, session: str):
        self.drift, self.rng, self.session = drift, rng, session
        self.yaw = float(rng.uniform(-math.pi, math.pi))  # the session frame's heading
        self.scale = 1.0 + float(rng.normal(0.0, drift))
        self.last: np.ndarray | None = None
        self.center = np.zeros(3)  # tracked, in the session's frame
        self.yaw_error = 0.0
        self.walked = 0.0

    def _turn(self, yaw: float) -> np.ndarray:
        c, s = math.cos(yaw), math.sin(yaw)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])

    def record(self, pose: ShotPose) -> dict:
        """The photo record's ``motion``: ``session``, ``center`` (m) and ``R_cam_from_session``
        of the camera in the session's frame, ``walked_m``."""
        c = np.asarray(pose.center, float)
        if self.last is not None:
            step = c - self.last
            length = float(np.linalg.norm(step))
            self.walked += length
            self.yaw_error += float(self.rng.normal(0.0, self.drift * math.sqrt(length)))
            noise = self.rng.normal(0.0, self.drift * length, 3) * [1.0, 1.0, 0.5]
            self.center = (
                self.center + self.scale * (self._turn(self.yaw + self.yaw_error) @ step) + noise
            )
        self.last = c
        R = pose.rotation() @ self._turn(self.yaw + self.yaw_error).T
        return {
            "motion": {
                "session": self.session,
                "center": [round(float(v), 5) for v in self.center],
                "R_cam_from_session": [[round(float(v), 7) for v in row] for row in R],
                "walked_m": round(self.walked, 4),
            }
        }


def phone_motion(person: SimPerson, session: str) -> PhoneMotion | None:
    """The phone's motion tracking for one session (a round), or None for a phone without
    (``person_sim.motion_drift`` null)."""
    if person.cfg.motion_drift is None:
        return None
    return PhoneMotion(person.cfg.motion_drift, person.motion_rng, session)


def truth_record(pose: ShotPose) -> dict:
    """The capture log's ``truth`` of a person's photo (world frame; ``robot``: where the
    person stood and its heading, as for the robot)."""
    return {
        "robot": {"x": float(pose.center[0]), "y": float(pose.center[1]),
                  "theta": float(pose.heading)},
        "center": [float(v) for v in pose.center],
        "R_cam_from_world": pose.rotation().tolist(),
        "pitch": float(pose.pitch),
    }  # fmt: skip


# ---------------------------------------------------------------------------- round 0


def perimeter_walk(person: SimPerson, n: int, inset_m: float) -> list[ShotPose]:
    """Round 0 of a person (and the unguided baseline): ``n`` photos at even spacing along
    the walls of every room, ``inset_m`` from them, each facing into its room (square to the
    walls, their direction taken over ``TANGENT_SPAN_M``) at eye height, level; between two
    rooms the person walks through the doorway, photographing ahead as it goes, and in a
    corridor (a room whose walk encloses a strip narrower than ``inset_m``:
    :func:`_strip_width`) it photographs along it, up and back. Where
    furniture stands on the walk, the person stands at the nearest free spot (within
    ``STEP_ASIDE_M``; farther, that photo is not taken).

    A room's walk is its closed line at distance ``inset_m`` from the walls (the geometry
    high up, ``WALL_BAND``: furniture stays below; :func:`room_lines`). The rooms are walked
    nearest first from the room the walk starts in (the scene's start, else the largest),
    each from where the person came in; the photos are spaced evenly over the whole walk,
    rooms and passages alike.

    Raises:
        ValueError: no such line (the room is narrower than twice ``inset_m``).
    """
    lines = room_lines(person.walls, inset_m)
    if len(lines) == 1:  # one room: its walk from the line's own start
        return _loop_shots(person, lines[0], np.arange(n) * _length(lines[0], True) / n)
    legs = _room_tour(person, lines)
    step = sum(_length(leg, kind == "room") for kind, leg in legs) / n
    out: list[ShotPose] = []
    carried = 0.0  # walked since the last photo
    for kind, leg in legs:
        length = _length(leg, kind == "room")
        at = np.arange(step - carried if carried else 0.0, length, step)
        if kind == "room" and _strip_width(leg) < inset_m:  # a corridor: photograph along it
            out += _passage_shots(person, np.vstack([leg, leg[:1]]), at)
        else:
            out += (_loop_shots if kind == "room" else _passage_shots)(person, leg, at)
        carried = length - at[-1] if len(at) else carried + length
    return out[:n]


def _strip_width(line: np.ndarray) -> float:
    """Mean width (m) of the region a room's closed walk encloses (its area over half its
    length): about 0 in a corridor, where the walk runs up one side of a thin strip and back
    down the other, and a photo square to the wall would be a close-up of it."""
    x, y = line[:, 0], line[:, 1]
    area = 0.5 * abs(float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)))
    return 2 * area / max(_length(line, True), 1e-9)


def _length(line: np.ndarray, closed: bool) -> float:
    """Arc length (m) of the line (K, 2), closed (a room's walk) or open (a passage)."""
    pts = np.vstack([line, line[:1]]) if closed else line
    return float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))


def _loop_shots(person: SimPerson, line: np.ndarray, at: np.ndarray) -> list[ShotPose]:
    """Photos at arc lengths ``at`` along the closed line ``line``, facing into the room."""
    closed = np.vstack([line, line[:1]])
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(closed, axis=0), axis=1))])
    length = s[-1]

    def point(u: np.ndarray) -> np.ndarray:
        u = np.mod(u, length)
        return np.column_stack([np.interp(u, s, closed[:, 0]), np.interp(u, s, closed[:, 1])])

    pts = point(at)
    half = min(TANGENT_SPAN_M, length / 4) / 2
    tangent = point(at + half) - point(at - half)
    x, y = closed[:-1, 0], closed[:-1, 1]
    ccw = 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)) > 0
    inward = np.column_stack([-tangent[:, 1], tangent[:, 0]]) * (1.0 if ccw else -1.0)
    return _standing(person, pts, np.arctan2(inward[:, 1], inward[:, 0]))


def _passage_shots(person: SimPerson, line: np.ndarray, at: np.ndarray) -> list[ShotPose]:
    """Photos at arc lengths ``at`` along the open line ``line``, facing the way it goes."""
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(line, axis=0), axis=1))])

    def point(u: np.ndarray) -> np.ndarray:
        u = np.clip(u, 0.0, s[-1])
        return np.column_stack([np.interp(u, s, line[:, 0]), np.interp(u, s, line[:, 1])])

    half = TANGENT_SPAN_M / 2
    ahead = point(at + half) - point(at - half)
    return _standing(person, point(at), np.arctan2(ahead[:, 1], ahead[:, 0]))


def _standing(person: SimPerson, pts: np.ndarray, headings: np.ndarray) -> list[ShotPose]:
    z = person.scene.floor_z + person.eye_height_m
    out = []
    for p, h in zip(pts, headings, strict=True):
        stand = person.nearest_standable(p)
        if stand is not None:
            out.append(ShotPose(np.array([stand[0], stand[1], z]), float(h), 0.0))
    return out


def _room_tour(person: SimPerson, lines: list[np.ndarray]) -> list[tuple[str, np.ndarray]]:
    """The walk through every room: legs ``("room", closed line)`` and ``("pass", open
    line)`` in walking order. The first room holds the scene's start (else it is the
    longest line), from the point nearest it; round each room back to where the person came
    in, then on to the room nearest on foot from there (the person's map of where it fits,
    :meth:`SimPerson.can_stand`), entered where the passage arrives. A room no passage
    reaches is left out."""
    grid = _FootGrid(person)
    start = person.scene.start
    here, entry = 0, 0
    if start is not None:
        d = [np.linalg.norm(ln - [start.x, start.y], axis=1) for ln in lines]
        here = int(np.argmin([x.min() for x in d]))
        entry = int(np.argmin(d[here]))
    legs: list[tuple[str, np.ndarray]] = []
    left = set(range(len(lines))) - {here}
    while True:  # round the room back to where it came in, then on to the nearest room
        legs.append(("room", np.roll(lines[here], -entry, axis=0)))
        if not left:
            break
        best = grid.nearest(lines[here][entry : entry + 1], [lines[k] for k in sorted(left)])
        if best is None:
            break
        k, path, entry = best
        here = sorted(left)[k]
        left.discard(here)
        legs.append(("pass", path))
    return legs


class _FootGrid:
    """Where the person can walk, on a coarse grid (``FOOT_RES_M``), for the passages."""

    def __init__(self, person: SimPerson):
        m = person.map
        k = max(1, round(FOOT_RES_M / m.res))
        h, w = (np.array(m.clearance.shape) // k) * k
        c = m.clearance[:h, :w].reshape(h // k, k, w // k, k).min(axis=(1, 3))
        self.free = c >= person.cfg.clearance_m
        self.res = m.res * k
        self.origin = m.origin
        self.graph = self._graph()

    def _graph(self):
        """The free cells' 8-neighbour graph (edge weights in cells), sparse."""
        from scipy.sparse import coo_matrix

        ny, nx = self.free.shape
        idx = np.arange(ny * nx).reshape(ny, nx)
        rows, cols, wts = [], [], []
        for dj, di, wgt in ((0, 1, 1.0), (1, 0, 1.0), (1, 1, 2**0.5), (1, -1, 2**0.5)):
            a = self.free[: ny - dj, max(0, -di) : nx - max(0, di)]
            b = self.free[dj:, max(0, di) : nx - max(0, -di) or None]
            ok = a & b
            ia = idx[: ny - dj, max(0, -di) : nx - max(0, di)][ok]
            ib = idx[dj:, max(0, di) : nx - max(0, -di) or None][ok]
            rows += [ia, ib]
            cols += [ib, ia]
            wts += [np.full(len(ia), wgt)] * 2
        return coo_matrix((np.concatenate(wts), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(ny * nx,) * 2).tocsr()  # fmt: skip

    def _cells(self, xy: np.ndarray) -> np.ndarray:
        ij = np.floor((np.asarray(xy, float) - self.origin) / self.res).astype(int)
        ij[:, 0] = np.clip(ij[:, 0], 0, self.free.shape[1] - 1)
        ij[:, 1] = np.clip(ij[:, 1], 0, self.free.shape[0] - 1)
        return ij[:, 1] * self.free.shape[1] + ij[:, 0]

    def nearest(self, src: np.ndarray, targets: list[np.ndarray]):
        """The target line nearest ``src`` on foot: (its index, the path (P, 2) world xy
        from ``src`` to it, the index of the target line's point it arrives at); None when
        no target is reachable."""
        from scipy.sparse.csgraph import dijkstra

        nx = self.free.shape[1]
        srcs = np.unique(self._cells(src))
        srcs = srcs[self.free.ravel()[srcs]]
        if not len(srcs):
            return None
        dist, pred, _ = dijkstra(self.graph, indices=srcs, min_only=True, return_predecessors=True)
        best = None
        for k, line in enumerate(targets):
            cells = self._cells(line)
            d = dist[cells]
            j = int(np.argmin(d))
            if np.isfinite(d[j]) and (best is None or d[j] < best[0]):
                best = (float(d[j]), k, cells[j], j)
        if best is None:
            return None
        _, k, cell, j = best
        chain = [cell]
        while pred[chain[-1]] >= 0:
            chain.append(pred[chain[-1]])
        chain = np.array(chain[::-1])
        xy = self.origin + (np.column_stack([chain % nx, chain // nx]) + 0.5) * self.res
        return k, xy, j


def room_lines(obstacles: ObstacleMap, inset_m: float) -> list[np.ndarray]:
    """(K, 2) world xy of every room's closed line at clearance ``inset_m`` (m), longest
    first: the lines that enclose space the person can be in (a line around a solid, a
    pillar, encloses none).

    Raises:
        ValueError: no such line (the rooms are narrower than twice ``inset_m``).
    """
    import contourpy
    import cv2

    z = obstacles.clearance
    gen = contourpy.contour_generator(z=z, line_type=contourpy.LineType.Separate)
    lines = [ln for ln in gen.lines(inset_m) if len(ln) >= 4]
    rooms = []
    for ln in lines:
        inside = np.zeros(z.shape, np.uint8)
        cv2.fillPoly(inside, [np.round(ln).astype(np.int32).reshape(-1, 1, 2)], 1)
        inside = inside.astype(bool)
        if inside.any() and np.mean(z[inside] > inset_m) > 0.5:
            rooms.append(ln)
    if not rooms:
        raise ValueError(
            f"no walk at person_sim.perimeter_inset_m = {inset_m} m from the walls: the room "
            "is narrower; lower it"
        )
    rooms.sort(key=lambda ln: -float(np.sum(np.linalg.norm(np.diff(ln, axis=0), axis=1))))
    return [obstacles.origin + ln * obstacles.res for ln in rooms]  # (col, row) -> (x, y)


def resample_closed(line: np.ndarray, n: int) -> np.ndarray:
    """(n, 2) points evenly spaced by arc length along the closed polyline ``line`` (K, 2)."""
    closed = np.vstack([line, line[:1]]) if not np.allclose(line[0], line[-1]) else line
    seg = np.linalg.norm(np.diff(closed, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    at = np.arange(n) * s[-1] / n
    return np.column_stack([np.interp(at, s, closed[:, 0]), np.interp(at, s, closed[:, 1])])


# ------------------------------------------------------------- reading the guide's map


def map_to_world(
    map_centers: np.ndarray,
    true_centers: np.ndarray,
    inlier_m: float = RECOGNISE_M,
    seed: int = 0,
):
    """The person's reading of the guide's map: the similarity from the map frame to the
    world fitted on where its own photos registered and where it truly took them (a person
    recognises the places of its own photos). A map can hold photos registered metres off
    (a repeated texture, a folded run of photos); the person is not fooled by a few of them:
    the fit is the one most photos agree with within ``inlier_m`` (m, world), from minimal
    sets of three (RANSAC), refitted on those. Returns ``(s, R, t)``
    (:func:`~scenebot.geometry.similarity_fit`).

    Raises:
        ValueError: fewer than 3 photos in common.
    """
    src, dst = np.asarray(map_centers, float), np.asarray(true_centers, float)
    if len(src) < 3:
        raise ValueError(
            f"the person recognises only {len(src)} of its photos in the map: it "
            "needs 3 to read the guide's map"
        )
    rng = np.random.default_rng(seed)
    best = np.ones(len(src), bool)
    best_n = 0
    for _ in range(RANSAC_TRIES if len(src) > 3 else 1):
        pick = rng.choice(len(src), 3, replace=False) if len(src) > 3 else np.arange(3)
        s, R, t = similarity_fit(src[pick], dst[pick])
        inl = np.linalg.norm(s * src @ R.T + t - dst, axis=1) <= inlier_m
        if inl.sum() > best_n:
            best, best_n = inl, int(inl.sum())
    if best_n < 3:
        best = np.ones(len(src), bool)
    return similarity_fit(src[best], dst[best])


def shot_in_world(goal: dict, sim) -> ShotPose:
    """A shot of goals.json (map frame: x, y, z, theta, pitch) as a world pose via the
    similarity ``sim`` = (s, R, t)."""
    s, R, t = sim
    c = s * R @ np.array([goal["x"], goal["y"], goal.get("z", 0.0)], float) + t
    th, ph = float(goal["theta"]), float(goal.get("pitch", 0.0))
    d = R @ np.array([math.cos(ph) * math.cos(th), math.cos(ph) * math.sin(th), math.sin(ph)])
    return ShotPose(c, math.atan2(d[1], d[0]), math.asin(float(np.clip(d[2], -1, 1))))
