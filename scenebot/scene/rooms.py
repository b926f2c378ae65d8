"""The built-in ``rooms`` scenes: one procedurally generated room per seed (``world.seed``).

A suite of rooms varied where real rooms vary, to measure one set of settings on many
rooms instead of tuning it on one: rectangles and L shapes from 3 x 3 to 8 x 6 m, ceilings
2.4-3.0 m, and two rooms joined by a doorway (through a partition wall, its door leaf open
against the wall) or by a corridor; 3-10 pieces of furniture of varied heights (beds, tables,
desks and chairs on legs the robot drives under, bookcases, sofas, sideboards, wardrobes,
TV stands, cardboard boxes, plants); posters and pictures, windows (an emissive picture of a
landscape on the wall, like the office's), ceiling lights. No glass and no mirrors. The
surfaces come from families that stress the pipeline in different ways:

* walls: ``paint`` (plain paint with a faint texture: few features), ``wallpaper`` (a motif
  repeating every metre), ``tiles`` (a grid of glazed tiles repeating every 15-30 cm) and
  ``wood`` (panelling of planks);
* floors: ``carpet`` (fine speckle), ``parquet`` (rows of planks), ``tiles`` and ``wood``
  (boards with a long grain).

Seeds 1 to 8 are fixed recipes, so that any eight-scene suite covers every kind::

    seed  kind                 walls (per space)            floors
    1     rect, medium         paint                        parquet
    2     L                    wallpaper                    carpet
    3     rect, large          wallpaper                    tiles
    4     two rooms, doorway   paint | wallpaper            parquet | carpet
    5     L                    wood                         tiles
    6     two rooms, corridor  wallpaper | tiles | paint    carpet | tiles | wood
    7     rect, small          tiles                        tiles
    8     two rooms, doorway   wood | paint                 wood | carpet

Any other seed draws its kind and families at random. Sizes, furniture, doorways, windows
and textures always come from the seed: the same seed gives the same room.
:func:`describe` says what a seed gives (kind, size, families, furniture, start) without
building it; :func:`rooms` builds it.

Every room is closed (walls, floor and ceiling meet; windows are pictures on the wall), the
start pose is at least 0.45 m from anything, doorways are 0.85-1.0 m wide, and furniture
keeps 0.6 m from other furniture, the walls (unless it stands against one) and the doorways'
approaches, so the robot (0.30 m wide) reaches all the free floor from the start.
The floor is at z = 0, the plan lies in x, y >= 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from scenebot.robot.base import Pose2D
from scenebot.scene import textures as tx
from scenebot.scene.mesh import SceneBuilder, SceneMesh
from scenebot.scene.parts import (
    HomeMaterials,
    Layout,
    Rect,
    bed,
    bookcase,
    cabinet,
    chair,
    home_fittings,
    home_materials,
    material,
    on_wall,
    plant,
    sofa,
    strip,
    table_on_legs,
    wall_art,
    wall_with_baseboard,
)

WALL_FAMILIES = ("paint", "wallpaper", "tiles", "wood")
FLOOR_FAMILIES = ("carpet", "parquet", "tiles", "wood")
KINDS = ("rect", "L", "two rooms, doorway", "two rooms, corridor")
PARTITION_M = 0.12  # thickness of the wall between two rooms
LINTEL_Z_M = 2.05  # top of a doorway
GAP_M = 0.6  # furniture keeps this far from furniture, walls and the spots kept free
_SOLID = -2  # plan label of a partition wall's footprint

# seed -> (kind, size class of a rect, wall families, floor families), one family per space
_RECIPES = {
    1: ("rect", "medium", ("paint",), ("parquet",)),
    2: ("L", None, ("wallpaper",), ("carpet",)),
    3: ("rect", "large", ("wallpaper",), ("tiles",)),
    4: ("two rooms, doorway", None, ("paint", "wallpaper"), ("parquet", "carpet")),
    5: ("L", None, ("wood",), ("tiles",)),
    6: ("two rooms, corridor", None, ("wallpaper", "tiles", "paint"), ("carpet", "tiles", "wood")),
    7: ("rect", "small", ("tiles",), ("tiles",)),
    8: ("two rooms, doorway", None, ("wood", "paint"), ("wood", "carpet")),
}
_RECT_SIZES = {"small": ((3.0, 4.0), (3.0, 3.5)), "medium": ((4.0, 6.0), (3.5, 5.0)),
               "large": ((6.0, 8.0), (4.5, 6.0))}  # fmt: skip
# furniture against a wall: (width along the wall, depth, height) ranges (m)
_AGAINST_WALL = {
    "bed": ((0.9, 1.6), (1.95, 2.1), (0.77, 0.77)),
    "sofa": ((1.6, 2.2), (0.85, 0.95), (0.85, 0.85)),
    "bookcase": ((0.8, 1.2), (0.32, 0.4), (1.8, 2.0)),
    "wardrobe": ((1.0, 1.6), (0.55, 0.62), (1.9, 2.2)),
    "sideboard": ((0.9, 1.5), (0.4, 0.5), (0.7, 0.95)),
    "desk": ((1.0, 1.5), (0.6, 0.75), (0.74, 0.74)),
    "tv stand": ((1.0, 1.4), (0.4, 0.45), (1.15, 1.15)),
}
# free-standing furniture: (x, y, height) ranges (m)
_FREE_STANDING = {
    "table": ((1.0, 1.6), (0.7, 1.0), (0.75, 0.75)),
    "chair": ((0.46, 0.46), (0.46, 0.46), (0.92, 0.92)),
    "plant": ((0.6, 0.6), (0.6, 0.6), (1.2, 1.2)),
}
DRIVE_UNDER = ("bed", "desk", "table", "chair")  # on legs: the robot drives under them
_NO_TWO = ("bed", "sofa", "wardrobe", "tv stand", "desk")
_PICKS = ("bookcase", "sofa", "wardrobe", "sideboard", "desk", "tv stand", "table", "chair",
          "plant", "box", "box", "bookcase", "sideboard", "chair")  # fmt: skip


# ------------------------------------------------------------------------------ the plan
@dataclass(frozen=True)
class Zone:
    """A space of the plan.

    Attributes:
        name: ``room``, ``room A``/``room B``, ``corridor`` or ``doorway`` (the floor of a
            doorway through a partition).
        rects: its floor, non-overlapping rectangles (m).
        wall: wall family; ``None`` for a doorway (its sides are the partition's).
        floor: floor family.
    """

    name: str
    rects: tuple[Rect, ...]
    wall: str | None
    floor: str

    @property
    def area_m2(self) -> float:
        """Floor area (m^2)."""
        return sum((r[2] - r[0]) * (r[3] - r[1]) for r in self.rects)


@dataclass(frozen=True)
class WallSeg:
    """One straight wall of the plan's outline: from ``o`` along ``u`` (m), the room on the
    left of ``u``; ``zone`` indexes :attr:`RoomPlan.zones`."""

    o: tuple[float, float]
    u: tuple[float, float]
    zone: int

    @property
    def length_m(self) -> float:
        """Length (m; walls are axis-aligned)."""
        return abs(self.u[0]) + abs(self.u[1])

    @property
    def normal(self) -> tuple[float, float]:
        """Unit normal into the room."""
        n = self.length_m
        return (-self.u[1] / n, self.u[0] / n)


@dataclass(frozen=True)
class Item:
    """A piece of furniture: ``kind``, floor rectangle (m), the side its front faces
    (``xpos``, ...; a piece against a wall has its back to it), height (m), zone index."""

    kind: str
    rect: Rect
    facing: str
    height_m: float
    zone: int


@dataclass
class RoomPlan:
    """Every geometric decision about one seed's room, before any triangle or texture.

    Attributes:
        seed: the seed.
        kind: one of :data:`KINDS`.
        height_m: floor to ceiling (m).
        zones: the spaces; zone 0 holds the start pose.
        solids: footprints of partition walls (m), solid from floor to ceiling.
        lintels: footprints of the wall above corridor mouths (from ``LINTEL_Z_M`` up).
        door_leaf: an open door's footprint against a partition, or ``None``.
        walls: the outline's walls.
        windows: ``(wall index, s, width, z0, height)`` (m along the wall, m).
        items: the furniture.
        keep_free: spots kept free of furniture (the start, the doorways' approaches).
        start: the robot's start pose.
    """

    seed: int
    kind: str
    height_m: float
    zones: list[Zone]
    solids: list[Rect] = field(default_factory=list)
    lintels: list[Rect] = field(default_factory=list)
    door_leaf: Rect | None = None
    walls: list[WallSeg] = field(default_factory=list)
    windows: list[tuple[int, float, float, float, float]] = field(default_factory=list)
    items: list[Item] = field(default_factory=list)
    keep_free: list[Rect] = field(default_factory=list)
    start: Pose2D = field(default_factory=lambda: Pose2D(0.0, 0.0, 0.0))

    @property
    def bounds(self) -> Rect:
        """The plan's bounding rectangle (m)."""
        rs = [r for z in self.zones for r in z.rects] + self.solids
        return (min(r[0] for r in rs), min(r[1] for r in rs), max(r[2] for r in rs),
                max(r[3] for r in rs))  # fmt: skip

    def describe(self) -> dict:
        """What this room is, as plain JSON-able data (for suite reports and tests)."""
        x0, y0, x1, y1 = self.bounds
        spaces = [z for z in self.zones if z.wall is not None]
        return {
            "seed": self.seed,
            "kind": self.kind,
            "size_m": [round(x1 - x0, 2), round(y1 - y0, 2)],
            "height_m": self.height_m,
            "floor_area_m2": round(sum(z.area_m2 for z in self.zones), 2),
            "spaces": [z.name for z in spaces],
            "walls": [z.wall for z in spaces],
            "floors": [z.floor for z in spaces],
            "furniture": [it.kind for it in self.items],
            "windows": len(self.windows),
            "start": [round(self.start.x, 3), round(self.start.y, 3), round(self.start.theta, 4)],
        }


def _q(x: float) -> float:
    """Round to 5 cm (plan dimensions)."""
    return float(np.round(x * 20) / 20)


def _recipe(seed: int, rng: np.random.Generator):
    """(kind, size class, wall families, floor families) of ``seed``."""
    if seed in _RECIPES:
        return _RECIPES[seed]
    kind = KINDS[int(rng.integers(0, len(KINDS)))]
    n = 3 if kind == "two rooms, corridor" else (2 if kind.startswith("two") else 1)
    walls = tuple(str(w) for w in rng.choice(WALL_FAMILIES, n))
    floors = tuple(str(f) for f in rng.choice(FLOOR_FAMILIES, n))
    return kind, str(rng.choice(list(_RECT_SIZES))), walls, floors


def _rect_zones(rng, size: str, walls, floors) -> list[Zone]:
    """A rectangular room of size class ``size`` (``_RECT_SIZES``)."""
    (w0, w1), (d0, d1) = _RECT_SIZES[size]
    W, D = _q(rng.uniform(w0, w1)), _q(rng.uniform(d0, d1))
    return [Zone("room", ((0.0, 0.0, W, D),), walls[0], floors[0])]


def _l_zones(rng, walls, floors) -> list[Zone]:
    """An L: a W x D rectangle without one corner's notch; the full-width bar comes first."""
    W, D = _q(rng.uniform(5.0, 8.0)), _q(rng.uniform(4.5, 6.0))
    nw, nd = _q(W * rng.uniform(0.4, 0.55)), _q(D * rng.uniform(0.4, 0.55))
    corner = int(rng.integers(0, 4))  # the notch: 0 NE, 1 NW, 2 SE, 3 SW
    north = corner < 2
    bar = (0.0, 0.0, W, D - nd) if north else (0.0, nd, W, D)
    ya, yb = (D - nd, D) if north else (0.0, nd)
    arm = (0.0, ya, W - nw, yb) if corner in (0, 2) else (nw, ya, W, yb)
    return [Zone("room", (bar, arm), walls[0], floors[0])]


def _doorway_plan(rng, walls, floors, plan: RoomPlan) -> None:
    """Rooms A (west) and B (east) on both sides of a partition with one doorway."""
    wa, wb = _q(rng.uniform(3.0, 4.5)), _q(rng.uniform(3.0, 4.5))
    da, db = _q(rng.uniform(3.0, 5.0)), _q(rng.uniform(3.0, 5.0))
    dmin, dw = min(da, db), _q(rng.uniform(0.85, 1.0))
    g0 = _q(rng.uniform(0.5, dmin - 0.5 - dw))
    g1, px1 = g0 + dw, wa + PARTITION_M
    plan.zones = [Zone("room A", ((0.0, 0.0, wa, da),), walls[0], floors[0]),
                  Zone("room B", ((px1, 0.0, px1 + wb, db),), walls[1], floors[1]),
                  Zone("doorway", ((wa, g0, px1, g1),), None, floors[0])]  # fmt: skip
    plan.solids = [(wa, 0.0, px1, g0), (wa, g1, px1, dmin)]
    # the door leaf stands open in room B against the partition, hinged at a jamb
    if dmin - g1 >= 0.9:
        plan.door_leaf = (px1, g1, px1 + 0.04, g1 + 0.85)
    else:
        plan.door_leaf = (px1, g0 - 0.85, px1 + 0.04, g0)
    plan.keep_free += [(wa - 1.0, g0 - 0.2, px1 + 1.0, g1 + 0.2), plan.door_leaf]


def _corridor_plan(rng, walls, floors, plan: RoomPlan) -> None:
    """Rooms A (west) and B (east) joined by a corridor, door frames at its mouths."""
    wa, wb = _q(rng.uniform(3.0, 4.2)), _q(rng.uniform(3.0, 4.2))
    da, db = _q(rng.uniform(3.0, 4.5)), _q(rng.uniform(3.0, 4.5))
    length, width = _q(rng.uniform(1.2, 2.4)), _q(rng.uniform(1.1, 1.4))
    c0 = _q(rng.uniform(0.4, min(da, db) - width - 0.4))
    c1, bx = c0 + width, wa + length
    plan.zones = [Zone("room A", ((0.0, 0.0, wa, da),), walls[0], floors[0]),
                  Zone("corridor", ((wa, c0, bx, c1),), walls[1], floors[1]),
                  Zone("room B", ((bx, 0.0, bx + wb, db),), walls[2], floors[2])]  # fmt: skip
    plan.lintels = [(wa, c0, wa + 0.1, c1), (bx - 0.1, c0, bx, c1)]
    plan.keep_free += [(wa - 1.0, c0 - 0.2, wa, c1 + 0.2), (bx, c0 - 0.2, bx + 1.0, c1 + 0.2)]


def outline(zones: list[Zone], solids: list[Rect]) -> list[WallSeg]:
    """The walls around the union of the zones' rectangles and the solid footprints.

    The plan is cut into the grid of all rectangle edges; a wall runs wherever a cell inside
    meets a cell outside, merged along runs of the same zone. Solids (partitions) get no
    walls: their boxes have faces of their own.

    Returns:
        The walls, each with the room on its left (so the outline runs counter-clockwise).
    """
    labelled = [(r, k) for k, z in enumerate(zones) for r in z.rects] + [
        (r, _SOLID) for r in solids
    ]
    xs = sorted({v for r, _ in labelled for v in (r[0], r[2])})
    ys = sorted({v for r, _ in labelled for v in (r[1], r[3])})
    lab = np.full((len(ys) + 1, len(xs) + 1), -1)  # padded by one cell of outside
    cx, cy = np.diff(xs) / 2 + xs[:-1], np.diff(ys) / 2 + ys[:-1]
    for (x0, y0, x1, y1), k in labelled:
        rows = np.nonzero((cy > y0) & (cy < y1))[0] + 1
        cols = np.nonzero((cx > x0) & (cx < x1))[0] + 1
        lab[np.ix_(rows, cols)] = k
    walls = _runs(lab, xs, ys, vertical=True) + _runs(lab.T, ys, xs, vertical=False)
    return [w for w in walls if w.zone != _SOLID]


def _runs(lab: np.ndarray, xs, ys, vertical: bool) -> list[WallSeg]:
    """Walls on the grid lines ``x = xs[i]`` (rows of ``lab`` along ``ys``); with
    ``vertical=False`` the roles of x and y are swapped (``lab`` transposed)."""
    out = []
    for i, x in enumerate(xs):
        run = None  # (key, start index)
        keys = []
        for j in range(len(ys) - 1):
            a, c = lab[j + 1, i], lab[j + 1, i + 1]
            keys.append(
                (c, 1) if a == -1 and c != -1 else ((a, -1) if c == -1 and a != -1 else None)
            )
        keys.append(None)
        for j, key in enumerate(keys):
            if run is not None and key != run[0]:
                (zone, side), j0 = run
                out.append(_seg(x, ys[j0], ys[j], side, vertical, int(zone)))
                run = None
            if run is None and key is not None:
                run = (key, j)
    return out


def _seg(x: float, y0: float, y1: float, side: int, vertical: bool, zone: int) -> WallSeg:
    """The wall on line ``x`` from ``y0`` to ``y1``, the room on side ``side`` (+1: towards
    larger x); axes swapped when not ``vertical``."""
    if vertical:  # the room on the left: a room at +x means a wall running towards -y
        o, u = ((x, y1), (0.0, y0 - y1)) if side > 0 else ((x, y0), (0.0, y1 - y0))
    else:  # the line y = x: a room at +y means a wall running towards +x
        o, u = ((y0, x), (y1 - y0, 0.0)) if side > 0 else ((y1, x), (y0 - y1, 0.0))
    return WallSeg(o, u, zone)


# ----------------------------------------------------------------- start, windows, furniture
def _start(rng: np.random.Generator, plan: RoomPlan) -> None:
    """The start pose near the middle of zone 0's first rectangle, 0.9 m around it kept free."""
    x0, y0, x1, y1 = plan.zones[0].rects[0]
    x = (x0 + x1) / 2 + float(rng.uniform(-0.2, 0.2))
    y = (y0 + y1) / 2 + float(rng.uniform(-0.2, 0.2))
    plan.start = Pose2D(x, y, float(rng.uniform(0, 2 * math.pi)))
    plan.keep_free.append((x - 0.45, y - 0.45, x + 0.45, y + 0.45))


def _windows(rng: np.random.Generator, plan: RoomPlan) -> None:
    """One or two windows per room (one when there are two rooms), on distinct walls."""
    rooms = [k for k, z in enumerate(plan.zones) if z.name.startswith("room")]
    for k in rooms:
        walls = [i for i, w in enumerate(plan.walls) if w.zone == k and w.length_m >= 1.6]
        n = 1 if len(rooms) > 1 else int(rng.integers(1, 3))
        for i in rng.permutation(walls)[:n]:
            length = plan.walls[i].length_m
            w = min(float(rng.uniform(0.9, 1.5)), length - 0.6)
            s = float(rng.uniform(0.3, length - w - 0.3))
            z0 = float(rng.uniform(0.8, 1.0))
            h = float(rng.uniform(1.1, min(1.5, plan.height_m - z0 - 0.25)))
            plan.windows.append((int(i), s, w, z0, h))


_OPPOSITE = {"xneg": "xpos", "xpos": "xneg", "yneg": "ypos", "ypos": "yneg"}
_SIDE_OF = {(1, 0): "xpos", (-1, 0): "xneg", (0, 1): "ypos", (0, -1): "yneg"}


@dataclass(frozen=True)
class _Spot:
    """A candidate piece of furniture: the item and whether its back stands against a wall."""

    item: Item
    at_wall: bool


def _dims(rng: np.random.Generator, kind: str) -> tuple[float, float, float]:
    """(width or x, depth or y, height) of a new ``kind`` (m)."""
    if kind == "box":
        w, d = rng.uniform(0.3, 0.55, 2)
        return float(w), float(d), float(rng.uniform(0.25, 0.5))
    table = _AGAINST_WALL.get(kind) or _FREE_STANDING[kind]
    return tuple(round(float(rng.uniform(lo, hi)), 2) for lo, hi in table)  # type: ignore[return-value]


def _at_wall(rng: np.random.Generator, plan: RoomPlan, zone: int, kind: str) -> _Spot | None:
    """``kind`` with its back against a random wall of ``zone``, in a corner or anywhere."""
    w, d, h = _dims(rng, kind)
    walls = [s for s in plan.walls if s.zone == zone and s.length_m >= w + 0.04]
    if not walls:
        return None
    seg = walls[int(rng.integers(0, len(walls)))]
    length, r = seg.length_m, float(rng.random())
    if r < 0.6:  # in a corner: at either end of the wall
        s = 0.02 if r < 0.3 else length - w - 0.02
    else:
        s = float(rng.uniform(0.02, length - w - 0.02))
    t = np.array(seg.u) / length
    n = np.array(seg.normal)
    p0 = np.array(seg.o) + s * t + 0.02 * n
    p1 = p0 + w * t + d * n
    lo, hi = np.minimum(p0, p1), np.maximum(p0, p1)
    rect = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
    facing = _SIDE_OF[(round(n[0]), round(n[1]))]
    return _Spot(Item(kind, rect, facing, h, zone), True)


def _free_standing(rng: np.random.Generator, plan: RoomPlan, zone: int, kind: str) -> _Spot:
    """``kind`` at a random spot of ``zone``, facing a random side."""
    w, d, h = _dims(rng, kind)
    rects = plan.zones[zone].rects
    area = np.array([(r[2] - r[0]) * (r[3] - r[1]) for r in rects])
    x0, y0, x1, y1 = rects[int(rng.choice(len(rects), p=area / area.sum()))]
    x = float(rng.uniform(x0 + 0.02, max(x1 - w - 0.02, x0 + 0.02)))
    y = float(rng.uniform(y0 + 0.02, max(y1 - d - 0.02, y0 + 0.02)))
    facing = ("xpos", "xneg", "ypos", "yneg")[int(rng.integers(0, 4))]
    return _Spot(Item(kind, (x, y, x + w, y + d), facing, h, zone), False)


class _Raster:
    """The plan's free floor (all zones) and each zone's floor on a 2 cm grid, for checks."""

    RES = 0.02

    def __init__(self, plan: RoomPlan):
        x0, y0, x1, y1 = plan.bounds
        self.origin = np.array([x0, y0])
        nx, ny = int(np.ceil((x1 - x0) / self.RES)), int(np.ceil((y1 - y0) / self.RES))
        cx = x0 + (np.arange(nx) + 0.5) * self.RES
        cy = y0 + (np.arange(ny) + 0.5) * self.RES
        self.zone = np.full((ny, nx), -1)
        for k, z in enumerate(plan.zones):
            for r in z.rects:
                self.zone[np.ix_((cy > r[1]) & (cy < r[3]), (cx > r[0]) & (cx < r[2]))] = k
        self.cx, self.cy = cx, cy

    def cells(self, rect: Rect) -> np.ndarray:
        """Zone labels of the cells whose centres lie in ``rect`` (-1: outside the plan)."""
        x0, y0, x1, y1 = rect
        inside = self.zone[np.ix_((self.cy > y0) & (self.cy < y1), (self.cx > x0) & (self.cx < x1))]
        pad = (self.cx[0] > x0) or (self.cx[-1] < x1) or (self.cy[0] > y0) or (self.cy[-1] < y1)
        return np.append(inside.ravel(), -1) if pad else inside.ravel()


def _fits(spot: _Spot, raster: _Raster, layout: Layout) -> bool:
    """Whether a spot lies in its zone, ``GAP_M`` from other furniture and the spots kept
    free, and with each side (but its back) ``GAP_M`` from walls or touching one."""
    it = spot.item
    x0, y0, x1, y1 = it.rect
    if not layout.fits(x0, y0, x1, y1, gap=GAP_M) or np.any(raster.cells(it.rect) != it.zone):
        return False
    back = _OPPOSITE[it.facing] if spot.at_wall else None
    for side in ("xneg", "xpos", "yneg", "ypos"):
        if side == back:
            continue
        moat = _beyond(it.rect, side, 0.0, GAP_M)
        if np.all(raster.cells(moat) >= 0):
            continue
        if np.any(raster.cells(_beyond(it.rect, side, 0.03, 0.07)) >= 0):
            return False  # neither open nor touching a wall: a narrow slot
    return True


def _beyond(rect: Rect, side: str, a: float, b: float) -> Rect:
    """The strip from ``a`` to ``b`` m outside ``rect``'s side ``side``, as long as the side."""
    x0, y0, x1, y1 = rect
    return {"xneg": (x0 - b, y0, x0 - a, y1), "xpos": (x1 + a, y0, x1 + b, y1),
            "yneg": (x0, y0 - b, x1, y0 - a), "ypos": (x0, y1 + a, x1, y1 + b)}[side]  # fmt: skip


def _spot(rng: np.random.Generator, plan: RoomPlan, zone: int, kind: str) -> _Spot | None:
    """A candidate spot for ``kind`` in ``zone`` (a box stands by a wall three times in five)."""
    if kind in _AGAINST_WALL or (kind == "box" and rng.random() < 0.6):
        return _at_wall(rng, plan, zone, kind)
    return _free_standing(rng, plan, zone, kind)


def _place(rng, plan: RoomPlan, raster: _Raster, layout: Layout, zone: int, kind: str) -> bool:
    """Place one ``kind`` in ``zone`` where it fits (40 tries); whether it was placed."""
    for _ in range(40):
        spot = _spot(rng, plan, zone, kind)
        if spot is not None and _fits(spot, raster, layout):
            plan.items.append(spot.item)
            layout.add(*spot.item.rect)
            return True
    return False


def _furnish(rng: np.random.Generator, plan: RoomPlan) -> None:
    """3-10 pieces of furniture, shared among the rooms by floor area.

    Each room gets first a piece the robot drives under (a bed in a room of 10 m^2 or more
    half of the time, else a table or a desk), then random picks; beds, sofas, wardrobes, TV
    stands and desks come at most once per room. Boxes fill up to three pieces where the
    picks did not fit (a small room).
    """
    raster, layout = _Raster(plan), Layout(list(plan.keep_free))
    rooms = [k for k, z in enumerate(plan.zones) if z.name.startswith("room")]
    areas = [plan.zones[k].area_m2 for k in rooms]
    target = int(np.clip(round(sum(areas) / 3.0) + rng.integers(-1, 2), 3, 10))
    for k, area in zip(rooms, areas, strict=True):
        want = max(1, round(target * area / sum(areas)))
        big = area >= 10.0 and rng.random() < 0.5
        first = "bed" if big else ("table", "desk")[int(rng.integers(0, 2))]
        picks = [first, *(str(p) for p in rng.choice(_PICKS, 11))]
        placed: list[str] = []
        for kind in picks:
            if len(placed) >= want or len(plan.items) >= 10:
                break
            if kind in _NO_TWO and kind in placed:
                continue
            if _place(rng, plan, raster, layout, k, kind):
                placed.append(kind)
    for k in rooms * 3:
        if len(plan.items) >= 3:
            break
        _place(rng, plan, raster, layout, k, "box")


def room_plan(seed: int) -> RoomPlan:
    """The plan of ``seed``'s room (no triangles, no textures; fast)."""
    return _plan(seed, np.random.default_rng(seed))


def describe(seed: int) -> dict:
    """What ``seed``'s room is (:meth:`RoomPlan.describe`): kind, size, ceiling height, wall
    and floor families per space, furniture, windows, start pose."""
    return room_plan(seed).describe()


def _plan(seed: int, rng: np.random.Generator) -> RoomPlan:
    """The plan, its random numbers drawn from ``rng`` in a fixed order (the textures follow)."""
    kind, size, walls, floors = _recipe(seed, rng)
    plan = RoomPlan(seed, kind, _q(rng.uniform(2.4, 3.0)), [])
    if kind == "rect":
        plan.zones = _rect_zones(rng, size, walls, floors)
    elif kind == "L":
        plan.zones = _l_zones(rng, walls, floors)
    elif kind == "two rooms, doorway":
        _doorway_plan(rng, walls, floors, plan)
    else:
        _corridor_plan(rng, walls, floors, plan)
    plan.walls = outline(plan.zones, plan.solids)
    _start(rng, plan)
    _windows(rng, plan)
    _furnish(rng, plan)
    return plan


# -------------------------------------------------------------------------------- building
_PAINT = ((232, 228, 218), (214, 222, 228), (226, 232, 214), (236, 224, 212), (222, 222, 224))
_PAPER = (((228, 222, 200), (150, 160, 120)), ((200, 214, 226), (120, 140, 170)),
          ((226, 220, 200), (160, 120, 80)), ((236, 228, 234), (170, 110, 140)))  # fmt: skip
_GLAZE = ((234, 234, 230), (200, 220, 232), (212, 228, 206), (132, 140, 150), (236, 222, 200))
_FLOOR_UV_M = {"carpet": 0.5, "parquet": 1.2, "tiles": 0.8, "wood": 0.9}


def _wall_texture(rng: np.random.Generator, family: str) -> np.ndarray:
    """A wall texture of ``family`` (repeating every metre on the wall)."""
    if family == "paint":
        return tx.plaster(rng, 256, tint=_PAINT[int(rng.integers(0, len(_PAINT)))])
    if family == "wallpaper":
        return tx.wallpaper(rng, *_PAPER[int(rng.integers(0, len(_PAPER)))])
    if family == "tiles":  # 4 x 4 tiles of 25 cm
        return tx.tiles(rng, 512, 4, _GLAZE[int(rng.integers(0, len(_GLAZE)))])
    # panelling: upright boards of 12.5 cm, most of them the full texture's height
    boards = tx.planks(rng, 512, rows=8, light=bool(rng.random() < 0.5), plank=(0.7, 1.0))
    return np.ascontiguousarray(np.rot90(boards))


def _floor_texture(rng: np.random.Generator, family: str) -> np.ndarray:
    """A floor texture of ``family`` (repeating every ``_FLOOR_UV_M[family]`` m)."""
    if family == "carpet":
        return tx.carpet(rng, 512)
    if family == "parquet":  # 8 rows of 15 cm planks
        return tx.planks(rng, 512, rows=8, light=bool(rng.random() < 0.7))
    if family == "tiles":  # 2 x 2 tiles of 40 cm
        glaze = _GLAZE[int(rng.integers(0, len(_GLAZE)))]
        return tx.tiles(rng, 512, 2, glaze, grout=(110, 108, 100))
    return tx.wood(rng, 512, light=bool(rng.random() < 0.6))


@dataclass
class _Materials(HomeMaterials):
    """Indices of a room's materials in the builder: per zone, then shared ones."""

    walls: list[int | None]
    floors: list[int]
    ceiling: int
    fabric: int
    cover: int
    wardrobe: int
    sideboard: int
    ceiling_uv_m: float


def _materials(b: SceneBuilder, rng: np.random.Generator, plan: RoomPlan) -> _Materials:
    """The room's materials, their textures drawn in this order."""
    walls = [None if z.wall is None
             else material(b, f"wall_{k}_{z.wall}", _wall_texture(rng, z.wall))
             for k, z in enumerate(plan.zones)]  # fmt: skip
    floors = [material(b, f"floor_{k}_{z.floor}", _floor_texture(rng, z.floor))
              for k, z in enumerate(plan.zones)]  # fmt: skip
    tiles = rng.random() < 0.4
    ceiling = tx.ceiling_tiles(rng, 512) if tiles else tx.plaster(rng, 256, tint=(238, 238, 234))
    return _Materials(
        walls=walls,
        floors=floors,
        ceiling=material(b, "ceiling", ceiling),
        **home_materials(b, rng),  # arguments are evaluated in order: the draws too
        fabric=material(b, "sofa_fabric", tx.fabric(rng)),
        cover=material(b, "bed_cover", tx.fabric(rng)),
        wardrobe=material(b, "wardrobe_doors", tx.cabinet_front(rng, 2, light=True)),
        sideboard=material(b, "sideboard_doors", tx.cabinet_front(rng, 3, 768, 384, light=False)),
        **home_fittings(b, rng),
        ceiling_uv_m=0.6 if tiles else 1.0,
    )


def _shell(b: SceneBuilder, plan: RoomPlan, m: _Materials) -> None:
    """Floors (per zone), the ceiling, the outline's walls with baseboards, and the lights.

    Floor and ceiling textures run on across the rectangles of a zone (uv offsets from the
    world position), so an L's floor has no seam.
    """
    H, c = plan.height_m, m.ceiling_uv_m
    for k, z in enumerate(plan.zones):
        s = _FLOOR_UV_M[z.floor]
        for x0, y0, x1, y1 in z.rects:
            b.quad([x0, y0, 0], [x1 - x0, 0, 0], [0, y1 - y0, 0], m.floors[k], uv_size=(s, s),
                   uv_offset=(x0 / s, -y1 / s))  # fmt: skip
    for x0, y0, x1, y1 in [r for z in plan.zones for r in z.rects] + plan.solids:
        b.quad([x0, y0, H], [0, y1 - y0, 0], [x1 - x0, 0, 0], m.ceiling, uv_size=(c, c),
               uv_offset=(y0 / c, -x1 / c))  # fmt: skip
    for w in plan.walls:
        wall_with_baseboard(b, [*w.o, 0.0], [*w.u, 0.0], H, m.walls[w.zone], m.base)
    for z in plan.zones:
        if z.wall is None:
            continue
        for x0, y0, x1, y1 in z.rects:
            nx = int(np.clip(round((x1 - x0) / 3.0), 1, 2))
            ny = int(np.clip(round((y1 - y0) / 3.0), 1, 2))
            for i in range(nx):
                for j in range(ny):
                    lx, ly = x0 + (i + 0.5) * (x1 - x0) / nx, y0 + (j + 0.5) * (y1 - y0) / ny
                    b.quad([lx - 0.25, ly - 0.25, H - 0.005], [0, 0.5, 0], [0.5, 0, 0], m.light)
                    b.light([lx, ly, H - 0.1])


def _doors(b: SceneBuilder, plan: RoomPlan, m: _Materials) -> None:
    """Partition walls (solid boxes), the wall above doorways and corridor mouths, the door."""
    H = plan.height_m
    rooms = [k for k, z in enumerate(plan.zones) if z.name.startswith("room")]
    west, east = (m.walls[rooms[0]], m.walls[rooms[-1]])
    for x0, y0, x1, y1 in plan.solids:
        b.box([x0, y0, 0], [x1, y1, H], {"xneg": west, "xpos": east, "side": west}, (1.0, 1.0),
              skip=("bottom", "top"))  # fmt: skip
    for z in plan.zones:
        if z.wall is None:  # the doorway through the partition
            x0, y0, x1, y1 = z.rects[0]
            b.box([x0, y0, LINTEL_Z_M], [x1, y1, H], west, (1.0, 1.0), skip=("top", "yneg", "ypos"))
    corridor = next((k for k, z in enumerate(plan.zones) if z.name == "corridor"), None)
    for x0, y0, x1, y1 in plan.lintels:
        b.box([x0, y0, LINTEL_Z_M], [x1, y1, H], m.walls[corridor], (1.0, 1.0),
              skip=("top", "yneg", "ypos"))  # fmt: skip
    if plan.door_leaf is not None:
        x0, y0, x1, y1 = plan.door_leaf
        b.box([x0, y0, 0.0], [x1, y1, 2.0], m.door, (0.84, 2.0))


def _decorate(b: SceneBuilder, rng: np.random.Generator, plan: RoomPlan, m: _Materials) -> None:
    """Windows, then posters and pictures: per space, one for every 3.5 m of its walls (at
    least two), at free spots of its walls."""
    walls = [([*w.o, 0.0], [*w.u, 0.0]) for w in plan.walls]
    occupied: dict[int, list[tuple[float, float]]] = {k: [] for k in range(len(walls))}
    for k, s, w, z0, h in plan.windows:
        on_wall(b, walls[k], s, z0, w, h, m.window)
        occupied[k].append((s, s + w))
    for zone in range(len(plan.zones)):
        own = [k for k, w in enumerate(plan.walls) if w.zone == zone]
        if not own:
            continue
        lengths = [plan.walls[k].length_m for k in own]
        n_art = max(2, round(sum(lengths) / 3.5))
        taken = {i: occupied[k] for i, k in enumerate(own)}
        wall_art(b, rng, [walls[k] for k in own], lengths, taken, n_max=n_art, tag=f"{zone}_")


def _item(b: SceneBuilder, rng: np.random.Generator, it: Item, m: _Materials) -> None:
    """Build one piece of furniture (drawing the textures it needs: books, cardboard)."""
    x0, y0, x1, y1 = it.rect
    back = _OPPOSITE[it.facing]
    top = {"top": m.wood, "side": m.dark}
    if it.kind == "bed":
        bed(b, it.rect, back, 0.45, m.dark, m.cover)
    elif it.kind == "sofa":
        sofa(b, it.rect, back, m.fabric)
    elif it.kind == "bookcase":
        bookcase(b, rng, m.dark, it.rect, it.facing, height=it.height_m)
    elif it.kind == "wardrobe":
        cabinet(b, it.rect, it.height_m, it.facing, m.wardrobe, m.wood)
    elif it.kind == "sideboard":
        cabinet(b, it.rect, it.height_m, it.facing, m.sideboard, m.dark)
    elif it.kind in ("desk", "table"):
        table_on_legs(b, it.rect, it.height_m, top, m.steel)
        if it.kind == "desk":
            bk = material(b, f"desk_books_{len(b.materials)}", tx.books(rng, 512, 128))
            cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
            b.box([cx - 0.15, cy - 0.15, it.height_m], [cx + 0.15, cy + 0.15, it.height_m + 0.14],
                  bk, None)  # fmt: skip
    elif it.kind == "tv stand":
        b.box([x0, y0, 0], [x1, y1, 0.5], m.wood, (0.6, 0.6))
        sx0, sy0, sx1, sy1 = strip(strip(it.rect, back, 0.2), it.facing, 0.08)  # the screen
        inset = 0.1 if back[0] == "y" else 0.0, 0.1 if back[0] == "x" else 0.0
        b.box(
            [sx0 + inset[0], sy0 + inset[1], 0.5],
            [sx1 - inset[0], sy1 - inset[1], 1.15],
            m.tv,
            None,
        )
    elif it.kind == "chair":
        chair(b, x0, y0, x1 - x0, back, it.height_m, m.fabric, m.steel)
    elif it.kind == "plant":
        plant(b, ((x0 + x1) / 2, (y0 + y1) / 2), m.pot, m.leaves)
    else:  # a cardboard box
        box = material(b, f"cardboard_{len(b.materials)}", tx.cardboard(rng))
        b.box([x0, y0, 0], [x1, y1, it.height_m], box, None)


def rooms(seed: int) -> SceneMesh:
    """Generate ``seed``'s room (see the module doc for what the seeds give).

    The generator draws every random number from one generator in a fixed order: the plan
    (:func:`room_plan`), then the materials, decorations and furniture textures; reordering
    the steps changes the room of every seed.

    Args:
        seed: generator seed (``world.seed``); the same seed gives the same room, textures
            included.

    Returns:
        The scene (named ``rooms<seed>``), with ``start`` set to the plan's start pose.
    """
    rng = np.random.default_rng(seed)
    plan = _plan(seed, rng)
    b = SceneBuilder(f"rooms{seed}")
    m = _materials(b, rng, plan)
    _shell(b, plan, m)
    _doors(b, plan, m)
    _decorate(b, rng, plan, m)
    for it in plan.items:
        _item(b, rng, it, m)
    return b.build(floor_z=0.0, start=plan.start)
