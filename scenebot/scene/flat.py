"""The built-in ``flat`` scene: two rooms and a corridor, generated deterministically from a seed.

A second world for the evaluation, unlike the office's single open room: a living room and
a bedroom side by side (an interior wall between them), both opening through a doorway onto
a corridor that runs along them. Door leaves stand open beside the doorways, lintels close
the wall above them, and furniture (sofa, coffee table on legs, bookcase, TV stand, bed,
wardrobe, desk and chair, cabinets, boxes, a plant) hides parts of the rooms from most
viewpoints. Textured like the office (:mod:`scenebot.scene.textures`: carpet, parquet, wood,
fabric, books, posters, pictures, cardboard), except that the walls carry patterned
wallpaper (:func:`~scenebot.scene.textures.wallpaper`) rather than plain paint: the rooms are
small, so photos often face a wall from close by, and with plain paint a third of round 0's
photos did not register.
The desk and the chair stand on legs: the robot (0.40 m tall) drives under them.

Plan (metres, floor at z = 0, ceiling at ``ROOM_HEIGHT_M``; the seed jitters the doorways and
furniture by a few decimetres)::

    y = 5.0 +--------------------------------------------------+
            |                    corridor                       |
    y = 3.75+-----+  door  +------------+------+  door  +-------+
    y = 3.6 |        living room        |       bedroom          |
            |    ([0, 4.0] x [0, 3.6])   |  ([4.15, 8] x [0, 3.6])|
    y = 0   +---------------------------+------------------------+
           x = 0                      4.0 4.15                   8.0

The start pose is in the living room, between the sofa's coffee table and the doorway.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from scenebot.robot.base import Pose2D
from scenebot.scene import textures as tx
from scenebot.scene.mesh import SceneBuilder, SceneMesh
from scenebot.scene.parts import (
    HomeMaterials,
    Layout,
    bookcase,
    boxes,
    chair,
    home_fittings,
    home_materials,
    material,
    plant,
    sofa,
    table_on_legs,
    wall_with_baseboard,
)

ROOM_HEIGHT_M = 2.5
FLAT_W_M = 8.0  # x extent
FLAT_D_M = 5.0  # y extent
PARTITION_X = (4.0, 4.15)  # wall between the rooms
CORRIDOR_WALL_Y = (3.6, 3.75)  # wall between the rooms and the corridor
DOOR_WIDTH_M = 0.95
LINTEL_Z_M = 2.05


@dataclass
class _Materials(HomeMaterials):
    """Indices of the flat's fixed materials in the builder."""

    carpet: int
    parquet: int
    corridor_carpet: int
    ceiling: int
    wall_a: int  # living room
    wall_b: int  # bedroom
    wall_c: int  # corridor
    sofa: int
    bed: int


def _flat_materials(b: SceneBuilder, rng: np.random.Generator) -> _Materials:
    """The fixed materials, their textures drawn in this order."""
    return _Materials(
        carpet=material(b, "carpet", tx.carpet(rng, 512)),
        parquet=material(b, "parquet", tx.wood(rng, 512, light=True)),
        corridor_carpet=material(b, "corridor_carpet", tx.carpet(rng, 512)),
        ceiling=material(b, "ceiling", tx.plaster(rng, 256, tint=(236, 236, 232))),
        wall_a=material(b, "living_wallpaper", tx.wallpaper(rng, (228, 222, 200), (150, 160, 120))),
        wall_b=material(
            b, "bedroom_wallpaper", tx.wallpaper(rng, (200, 214, 226), (120, 140, 170))
        ),
        wall_c=material(
            b, "corridor_wallpaper", tx.wallpaper(rng, (226, 220, 200), (160, 120, 80))
        ),
        **home_materials(b, rng),  # arguments are evaluated in order: the draws too
        sofa=material(b, "sofa_fabric", tx.fabric(rng)),
        bed=material(b, "bed_fabric", tx.fabric(rng)),
        **home_fittings(b, rng),
    )


# ------------------------------------------------------------------------------- the shell
def _floors_and_ceiling(b: SceneBuilder, m: _Materials) -> None:
    """Floors (one per space) and the ceiling."""
    W, D, H = FLAT_W_M, FLAT_D_M, ROOM_HEIGHT_M
    px0, px1 = PARTITION_X
    cy0, cy1 = CORRIDOR_WALL_Y
    b.quad([0, 0, 0], [px0, 0, 0], [0, cy0, 0], m.carpet, uv_size=(0.5, 0.5))
    b.quad([px1, 0, 0], [W - px1, 0, 0], [0, cy0, 0], m.parquet, uv_size=(0.9, 0.9))
    b.quad([0, cy1, 0], [W, 0, 0], [0, D - cy1, 0], m.corridor_carpet, uv_size=(0.5, 0.5))
    b.quad([0, 0, H], [0, D, 0], [W, 0, 0], m.ceiling, uv_size=(1.0, 1.0))


def _outer_walls(b: SceneBuilder, m: _Materials) -> None:
    """Outer walls, papered per space they face, with baseboards."""
    W, D = FLAT_W_M, FLAT_D_M
    px0, px1 = PARTITION_X
    cy0, cy1 = CORRIDOR_WALL_Y
    wall_with_baseboard(
        b, [0, 0, 0], [px0, 0, 0], ROOM_HEIGHT_M, m.wall_a, m.base
    )  # living room, south
    wall_with_baseboard(
        b, [px1, 0, 0], [W - px1, 0, 0], ROOM_HEIGHT_M, m.wall_b, m.base
    )  # bedroom, south
    wall_with_baseboard(b, [W, 0, 0], [0, cy0, 0], ROOM_HEIGHT_M, m.wall_b, m.base)  # bedroom, east
    wall_with_baseboard(
        b, [W, cy1, 0], [0, D - cy1, 0], ROOM_HEIGHT_M, m.wall_c, m.base
    )  # corridor, east end
    wall_with_baseboard(
        b, [W, D, 0], [-W, 0, 0], ROOM_HEIGHT_M, m.wall_c, m.base
    )  # corridor, north
    wall_with_baseboard(
        b, [0, D, 0], [0, cy1 - D, 0], ROOM_HEIGHT_M, m.wall_c, m.base
    )  # corridor, west end
    wall_with_baseboard(
        b, [0, cy0, 0], [0, -cy0, 0], ROOM_HEIGHT_M, m.wall_a, m.base
    )  # living room, west


def _interior_walls(
    b: SceneBuilder, rng: np.random.Generator, m: _Materials
) -> list[tuple[float, float]]:
    """Interior walls: solid boxes with doorway gaps, lintels, thresholds and open doors.

    Returns:
        The doorways' x extents along the corridor wall: living room's, then bedroom's.
    """
    W, H = FLAT_W_M, ROOM_HEIGHT_M
    px0, px1 = PARTITION_X
    cy0, cy1 = CORRIDOR_WALL_Y
    door_a = float(np.round(rng.uniform(1.3, 2.2), 2))  # living-room doorway starts here (x)
    door_b = float(np.round(rng.uniform(5.0, 5.9), 2))  # bedroom doorway
    gaps = [(door_a, door_a + DOOR_WIDTH_M), (door_b, door_b + DOOR_WIDTH_M)]
    xs = [0.0, gaps[0][0], gaps[0][1], px0, px1, gaps[1][0], gaps[1][1], W]
    for k in (0, 2, 4, 6):
        x0, x1 = xs[k], xs[k + 1]
        if x1 - x0 > 1e-6:
            paper = m.wall_a if x1 <= px0 + 1e-6 else (m.wall_b if x0 >= px0 else m.wall_a)
            b.box([x0, cy0, 0], [x1, cy1, H], {"yneg": paper, "ypos": m.wall_c, "side": paper},
                  (1.0, 1.0), skip=("bottom", "top"))  # fmt: skip
    b.box([px0, cy0, 0], [px1, cy1, H], m.wall_a, (1.0, 1.0), skip=("bottom", "top"))
    for g0, g1 in gaps:
        b.box([g0, cy0, LINTEL_Z_M], [g1, cy1, H], m.wall_c, (1.0, 1.0), skip=("top",))
    b.box([px0, 0, 0], [px1, cy0, H], {"xneg": m.wall_a, "xpos": m.wall_b, "side": m.wall_a},
          (1.0, 1.0), skip=("bottom", "top"))  # fmt: skip
    for g0, g1 in gaps:  # thresholds: floor under the doorways
        b.quad([g0, cy0, 0], [g1 - g0, 0, 0], [0, cy1 - cy0, 0], m.parquet, uv_size=(0.9, 0.9))
    # Door leaves standing open into each room, hinged at the doorway's west jamb.
    for g0, _ in gaps:
        b.box([g0 + 0.02, cy0 - 0.84, 0.0], [g0 + 0.06, cy0, 2.0], m.door, (0.84, 2.0))
    return gaps


def _lights(b: SceneBuilder, m: _Materials) -> None:
    """Ceiling lights: one per room, two in the corridor."""
    W, D, H = FLAT_W_M, FLAT_D_M, ROOM_HEIGHT_M
    px0, px1 = PARTITION_X
    cy0, cy1 = CORRIDOR_WALL_Y
    for lx, ly in ((px0 / 2, cy0 / 2), ((px1 + W) / 2, cy0 / 2), (W / 4, (cy1 + D) / 2),
                   (3 * W / 4, (cy1 + D) / 2)):  # fmt: skip
        b.quad([lx - 0.25, ly - 0.25, H - 0.005], [0, 0.5, 0], [0.5, 0, 0], m.light)
        b.light([lx, ly, H - 0.1])


def _windows(b: SceneBuilder, m: _Materials) -> None:
    """Windows on the outer walls of both rooms (seen from inside: u runs right-to-left)."""
    W = FLAT_W_M
    b.quad([0.01, 1.4, 0.9], [0, 1.1, 0], [0, 0, 1.1], m.window)  # living room, west wall
    b.quad([W - 0.01, 3.3, 0.9], [0, -1.2, 0], [0, 0, 1.1], m.window)  # bedroom, east wall


def _pictures(b: SceneBuilder, rng: np.random.Generator) -> None:
    """Posters and pictures: the corridor walls and the rooms, at fixed spots."""
    W, D = FLAT_W_M, FLAT_D_M
    px0, px1 = PARTITION_X
    cy0, cy1 = CORRIDOR_WALL_Y
    hi, lo = (1.0, 1.3), (0.4, 0.9)  # bottom heights: above the corridor's cabinets
    spots = [((0.6, D), (1, 0), (0, -1), hi), ((3.0, D), (1, 0), (0, -1), hi),
             ((5.4, D), (1, 0), (0, -1), hi), ((W - 0.05, cy1), (-1, 0), (0, 1), hi),
             ((0.4, cy0), (1, 0), (0, -1), lo), ((px0, 0.4), (0, 1), (-1, 0), lo),
             ((px1, 2.0), (0, -1), (1, 0), lo), ((6.2, 0.0), (1, 0), (0, 1), lo),
             ((0.0, 3.4), (0, -1), (1, 0), lo), ((2.6, 0.0), (1, 0), (0, 1), hi),
             ((0.0, 0.95), (0, -1), (1, 0), hi), ((px0, 2.7), (0, 1), (-1, 0), lo)]  # fmt: skip
    for k, (p0, u, n, zr) in enumerate(spots):
        # the picture runs from p0 + s u along u, on the wall, facing n
        is_poster = rng.random() < 0.6
        w = float(rng.uniform(0.45, 0.7))
        h = w * (1.4 if is_poster else 0.75)
        tex = tx.poster(rng) if is_poster else tx.framed_picture(rng)
        m = material(b, f"{'poster' if is_poster else 'picture'}_{k}", tex)
        s = float(rng.uniform(0.05, 0.2))
        pp = np.array([p0[0] + s * u[0], p0[1] + s * u[1], float(rng.uniform(*zr))])
        pp += 0.01 * np.r_[n, 0]
        uu = np.array([u[0], u[1], 0.0]) * w
        if np.cross(uu, [0, 0, 1])[:2] @ np.asarray(n) < 0:  # keep the image upright, facing n
            pp, uu = pp + uu, -uu
        b.quad(pp, uu, [0, 0, h], m)


# ------------------------------------------------------------------------ living room furniture
def _sofa(b: SceneBuilder, rng: np.random.Generator, m: _Materials, layout: Layout) -> float:
    """A sofa against the south wall. Returns its west end (x, m)."""
    sx0 = float(rng.uniform(0.4, 0.9))
    sofa(b, (sx0, 0.05, sx0 + 2.0, 0.95), "yneg", m.sofa)
    layout.add(sx0, 0.05, sx0 + 2.0, 0.95)
    return sx0


def _coffee_table(b: SceneBuilder, m: _Materials, layout: Layout, tx0: float) -> None:
    """A coffee table on steel legs in front of the sofa, its west end at ``tx0``."""
    table_on_legs(b, (tx0, 1.35, tx0 + 1.0, 1.85), 0.42, {"top": m.wood, "side": m.dark}, m.steel)
    layout.add(tx0, 1.35, tx0 + 1.0, 1.85)


def _bookcase(b: SceneBuilder, rng: np.random.Generator, m: _Materials, layout: Layout) -> None:
    """A bookcase against the west wall, facing east, five shelves of books."""
    by0 = float(rng.uniform(0.9, 1.3))
    bookcase(b, rng, m.dark, (0.02, by0, 0.38, by0 + 1.0), "xpos", height=1.9, name="books_{k}")
    layout.add(0.02, by0, 0.38, by0 + 1.0)


def _tv(b: SceneBuilder, rng: np.random.Generator, m: _Materials, layout: Layout) -> None:
    """A TV stand and TV against the partition wall, facing west."""
    px0 = PARTITION_X[0]
    ty0 = float(rng.uniform(0.8, 1.4))
    b.box([px0 - 0.45, ty0, 0], [px0 - 0.02, ty0 + 1.3, 0.5], m.wood, (0.6, 0.6))
    b.box([px0 - 0.2, ty0 + 0.1, 0.5], [px0 - 0.12, ty0 + 1.2, 1.15], m.tv, None)
    layout.add(px0 - 0.45, ty0, px0 - 0.02, ty0 + 1.3)


def _plant(b: SceneBuilder, m: _Materials, layout: Layout) -> None:
    """A potted plant in the living room's south-east corner."""
    px0 = PARTITION_X[0]
    plant(b, (px0 - 0.3, 0.3), m.pot, m.leaves)
    layout.add(px0 - 0.6, 0.0, px0, 0.6)


def _living_room(
    b: SceneBuilder, rng: np.random.Generator, m: _Materials, door_a: float
) -> tuple[Layout, float]:
    """The living room's furniture, the doorway approach kept free.

    Returns:
        Its layout and the coffee table's west end (x, m; the start pose is east of it).
    """
    cy0 = CORRIDOR_WALL_Y[0]
    layout = Layout([(door_a - 0.2, cy0 - 1.0, door_a + DOOR_WIDTH_M + 0.2, cy0)])
    tx0 = _sofa(b, rng, m, layout) + 0.5
    _coffee_table(b, m, layout, tx0)
    _bookcase(b, rng, m, layout)
    _tv(b, rng, m, layout)
    _plant(b, m, layout)
    return layout, tx0


# ---------------------------------------------------------------------------- bedroom furniture
def _bed(b: SceneBuilder, rng: np.random.Generator, m: _Materials, layout: Layout) -> None:
    """A bed with a headboard against the east wall and a nightstand beside it."""
    W = FLAT_W_M
    bedy = float(rng.uniform(0.3, 0.8))
    b.box([W - 2.05, bedy, 0], [W - 0.05, bedy + 1.6, 0.55], m.bed, (0.8, 0.8))
    b.box([W - 0.12, bedy, 0.55], [W - 0.02, bedy + 1.6, 1.1], m.dark, (0.5, 0.5))
    layout.add(W - 2.05, bedy, W - 0.02, bedy + 1.6)
    b.box([W - 0.5, bedy + 1.7, 0], [W - 0.05, bedy + 2.1, 0.5], m.wood, (0.4, 0.4))  # nightstand
    layout.add(W - 0.5, bedy + 1.7, W - 0.05, bedy + 2.1)


def _wardrobe(b: SceneBuilder, rng: np.random.Generator, m: _Materials, layout: Layout) -> None:
    """A wardrobe against the south wall, next to the partition."""
    wx0 = PARTITION_X[1] + float(rng.uniform(0.05, 0.4))
    b.box([wx0, 0.02, 0], [wx0 + 1.2, 0.62, 2.0], {"ypos": m.wood, "side": m.dark}, (0.6, 1.0))
    layout.add(wx0, 0.02, wx0 + 1.2, 0.62)


def _desk(b: SceneBuilder, rng: np.random.Generator, m: _Materials, layout: Layout) -> float:
    """A desk on steel legs with books on it, against the partition north of the wardrobe.

    Returns:
        Its south end (y, m).
    """
    px1 = PARTITION_X[1]
    dy0 = float(rng.uniform(1.6, 2.1))
    dtop = 0.74
    desk_mats = {"top": m.wood, "side": m.dark}
    table_on_legs(b, (px1 + 0.02, dy0, px1 + 0.7, dy0 + 1.2), dtop, desk_mats, m.steel)
    bk = material(b, "desk_books", tx.books(rng, 512, 128))
    b.box([px1 + 0.1, dy0 + 0.8, dtop], [px1 + 0.4, dy0 + 1.1, dtop + 0.14], bk, None)
    layout.add(px1 + 0.02, dy0, px1 + 0.7, dy0 + 1.2)
    return dy0


def _desk_chair(b: SceneBuilder, m: _Materials, layout: Layout, dy0: float) -> None:
    """A chair on steel legs east of the desk whose south end is at ``dy0``."""
    cx0 = PARTITION_X[1] + 0.85
    cy = dy0 + 0.35
    chair(b, cx0, cy, 0.46, "xpos", 0.92, m.sofa, m.steel)
    layout.add(cx0, cy, cx0 + 0.46, cy + 0.46)


def _bedroom(b: SceneBuilder, rng: np.random.Generator, m: _Materials, door_b: float) -> Layout:
    """The bedroom's furniture, the doorway approach kept free. Returns its layout."""
    cy0 = CORRIDOR_WALL_Y[0]
    layout = Layout([(door_b - 0.2, cy0 - 1.0, door_b + DOOR_WIDTH_M + 0.2, cy0)])
    _bed(b, rng, m, layout)
    _wardrobe(b, rng, m, layout)
    dy0 = _desk(b, rng, m, layout)
    _desk_chair(b, m, layout, dy0)
    return layout


# --------------------------------------------------------------------------- corridor and boxes
def _corridor(b: SceneBuilder, rng: np.random.Generator, m: _Materials) -> None:
    """Two cabinets against the corridor's north wall, a vase on the second."""
    D = FLAT_D_M
    kx0 = float(rng.uniform(0.3, 1.0))
    b.box([kx0, D - 0.36, 0], [kx0 + 1.1, D - 0.02, 0.9], {"yneg": m.wood, "side": m.dark},
          (0.55, 0.45))  # fmt: skip
    sx = float(rng.uniform(4.6, 6.0))
    b.box([sx, D - 0.4, 0], [sx + 1.3, D - 0.02, 0.8], {"yneg": m.dark, "side": m.wood},
          (0.65, 0.4))  # fmt: skip
    vase = material(b, "vase", tx.flat((60, 90, 140)), specular=0.5)
    b.prism((sx + 0.3, D - 0.21), 0.08, 0.8, 1.1, 10, vase)


def flat(seed: int) -> SceneMesh:
    """Generate the two-room flat.

    The generator draws every random number from one generator in a fixed order: the steps
    below run in that order, and reordering them changes the scene of every seed.

    Args:
        seed: generator seed (``world.seed``); the same seed gives the same scene, textures
            included.

    Returns:
        The scene, with ``start`` set to a free pose in the living room.
    """
    rng = np.random.default_rng(seed)
    W = FLAT_W_M
    px0, px1 = PARTITION_X
    cy0 = CORRIDOR_WALL_Y[0]
    b = SceneBuilder("flat")
    m = _flat_materials(b, rng)
    _floors_and_ceiling(b, m)
    _outer_walls(b, m)
    (door_a, _), (door_b, _) = _interior_walls(b, rng, m)
    _lights(b, m)
    _windows(b, m)
    _pictures(b, rng)
    living, tx0 = _living_room(b, rng, m, door_a)
    bedroom = _bedroom(b, rng, m, door_b)
    _corridor(b, rng, m)

    start_xy = (tx0 + 1.5, 2.5)
    living.add(start_xy[0] - 0.5, start_xy[1] - 0.5, start_xy[0] + 0.5, start_xy[1] + 0.5)
    boxes(b, rng, living, (0.05, px0 - 0.05), (0.05, cy0 - 0.05), 2)
    boxes(b, rng, bedroom, (px1 + 0.05, W - 0.05), (0.05, cy0 - 0.05), 2)
    theta = float(rng.uniform(0, 2 * math.pi))
    return b.build(floor_z=0.0, start=Pose2D(start_xy[0], start_xy[1], theta))
