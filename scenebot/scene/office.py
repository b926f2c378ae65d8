"""The built-in ``office`` scene, generated deterministically from a seed.

A rectangular room (about 6 x 5 x 2.6 m) with carpet, ceiling tiles, painted walls, a door,
a window, posters, a whiteboard (shiny, nearly textureless), a cork board, framed pictures,
desks with metal legs, a bookcase, a metal filing cabinet (shiny), cardboard boxes, and a few
obstacles in the middle (boxes, a bin, a chair). The floor is at z = 0, the room spans
``[0, W] x [0, D]``.

The generator draws every random number from one generator in a fixed order (room size,
textures, wall decorations, furniture, start heading): the helpers below are called in that
order, and reordering them changes the scene of every seed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from scenebot.robot.base import Pose2D
from scenebot.scene import textures as tx
from scenebot.scene.mesh import SceneBuilder, SceneMesh
from scenebot.scene.parts import (
    Layout,
    Wall,
    bookcase,
    chair,
    material,
    on_wall,
    table_on_legs,
    wall_art,
    wall_with_baseboard,
)

ROOM_HEIGHT_M = 2.6


@dataclass
class _Materials:
    """Indices of the office's fixed materials in the builder."""

    carpet: int
    ceiling: int
    wall: int
    base: int
    wood: int
    dark: int
    steel: int
    cabinet: int
    board: int
    cork: int
    light: int
    window: int
    door: int
    bin: int
    fabric: int


def _office_materials(b: SceneBuilder, rng: np.random.Generator) -> _Materials:
    """The fixed materials, their textures drawn in this order."""
    return _Materials(
        carpet=material(b, "carpet", tx.carpet(rng, 512)),
        ceiling=material(b, "ceiling", tx.ceiling_tiles(rng, 512)),
        wall=material(b, "wall_paint", tx.plaster(rng, 256)),
        base=material(b, "baseboard", tx.metal(rng, 128, tint=(90, 88, 85))),
        wood=material(b, "desk_wood", tx.wood(rng, 1024, light=True)),
        dark=material(b, "dark_wood", tx.wood(rng, 512, light=False)),
        steel=material(b, "steel", tx.metal(rng, 256), specular=0.6, shininess=60),
        cabinet=material(
            b, "cabinet_metal", tx.metal(rng, 256, tint=(150, 160, 170)), specular=0.8
        ),
        board=material(b, "whiteboard", tx.whiteboard(rng), specular=0.9, shininess=120),
        cork=material(b, "cork", tx.cork(rng)),
        light=material(b, "ceiling_light", tx.flat((255, 252, 240)), emissive=True),
        window=material(b, "window", tx.framed_picture(rng, 512, 384), emissive=True),
        door=material(b, "door", tx.door(rng)),
        bin=material(b, "bin_plastic", tx.flat((45, 48, 52)), specular=0.7, shininess=80),
        fabric=material(b, "chair_fabric", tx.fabric(rng)),
    )


def _office_walls(W: float, D: float) -> list[Wall]:
    """The four walls, numbered 0..3 counter-clockwise from the one along y = 0."""
    return [
        ([0, 0, 0], [W, 0, 0]),
        ([W, 0, 0], [0, D, 0]),
        ([W, D, 0], [-W, 0, 0]),
        ([0, D, 0], [0, -D, 0]),
    ]


def _room_shell(b: SceneBuilder, m: _Materials, walls: list[Wall], W: float, D: float) -> None:
    """Floor, ceiling, painted walls with baseboards, and four ceiling lights."""
    H = ROOM_HEIGHT_M
    b.quad([0, 0, 0], [W, 0, 0], [0, D, 0], m.carpet, uv_size=(0.5, 0.5))
    b.quad([0, 0, H], [0, D, 0], [W, 0, 0], m.ceiling, uv_size=(0.6, 0.6))
    for o, u in walls:
        wall_with_baseboard(b, o, u, H, m.wall, m.base)
    for lx in (W / 3, 2 * W / 3):
        for ly in (D / 3, 2 * D / 3):
            b.quad([lx - 0.3, ly - 0.3, H - 0.005], [0, 0.6, 0], [0.6, 0, 0], m.light)
            b.light([lx, ly, H - 0.1])


def _wall_decorations(
    b: SceneBuilder, rng: np.random.Generator, m: _Materials, walls: list[Wall], W: float, D: float
) -> float:
    """Door (wall 2), window (wall 1), whiteboard (wall 0), cork (wall 3), then the art.

    Returns:
        Where the door starts along wall 2 (m).
    """
    door_s = float(rng.uniform(0.4, 1.0))
    on_wall(b, walls[2], door_s, 0.0, 0.9, 2.05, m.door)
    on_wall(b, walls[1], D * 0.5 - 0.8, 0.9, 1.6, 1.1, m.window)
    on_wall(b, walls[0], W * 0.5 - 0.8, 0.75, 1.6, 0.9, m.board)
    on_wall(b, walls[3], D * 0.5 - 0.6, 0.7, 1.2, 0.9, m.cork)
    occupied = {0: [(W * 0.5 - 0.8, W * 0.5 + 0.8)], 1: [(D * 0.5 - 0.8, D * 0.5 + 0.8)],
                2: [(door_s, door_s + 0.9)], 3: [(D * 0.5 - 0.6, D * 0.5 + 0.6)]}  # fmt: skip
    wall_art(b, rng, walls, [W, D, W, D], occupied, n_max=9)
    return door_s


def _desk(
    b: SceneBuilder,
    rng: np.random.Generator,
    m: _Materials,
    layout: Layout,
    x0: float,
    y0: float,
    x1: float,
    y1: float,
) -> None:
    """A desk on metal legs with a monitor and a stack of books on top."""
    top = 0.74
    table_on_legs(b, (x0, y0, x1, y1), top, {"top": m.wood, "side": m.dark}, m.steel)
    mx = x0 + (x1 - x0) * float(rng.uniform(0.25, 0.55))
    my = y0 + (y1 - y0) * 0.5
    b.box([mx, my - 0.05, top], [mx + 0.5, my + 0.05, top + 0.32], m.bin, None)
    bk = material(b, f"desk_books_{len(b.materials)}", tx.books(rng, 512, 128))
    b.box([x1 - 0.35, y0 + 0.1, top], [x1 - 0.1, y0 + 0.4, top + 0.12], bk, None)
    layout.add(x0, y0, x1, y1)


def _filing_cabinet(
    b: SceneBuilder, rng: np.random.Generator, m: _Materials, layout: Layout, W: float
) -> None:
    """A metal filing cabinet against wall 1."""
    fy = float(rng.uniform(0.4, 1.0))
    b.box([W - 0.62, fy, 0], [W - 0.02, fy + 0.47, 0.72], m.cabinet, (0.5, 0.35))
    layout.add(W - 0.62, fy, W - 0.02, fy + 0.47)


def _cardboard_boxes(
    b: SceneBuilder, rng: np.random.Generator, layout: Layout, W: float, D: float, door_s: float
) -> None:
    """Seven cardboard boxes: four along the walls, then three around the middle."""
    cx, cy = W / 2, D / 2
    placed = 0
    for _ in range(200):
        if placed >= 7:
            break
        sx, sy = rng.uniform(0.3, 0.6, 2)
        sz = float(rng.uniform(0.25, 0.55))
        middle = placed >= 4
        if middle:
            ang = rng.uniform(0, 2 * math.pi)
            r = rng.uniform(0.9, 1.5)
            x0, y0 = cx + r * math.cos(ang) - sx / 2, cy + r * math.sin(ang) - sy / 2
        else:
            x0, y0 = rng.uniform(0.05, W - sx - 0.05), rng.uniform(0.05, D - sy - 0.05)
            if min(x0, y0, W - x0 - sx, D - y0 - sy) > 0.1:
                continue  # along a wall only
        if x0 < 0.05 or y0 < 0.05 or x0 + sx > W - 0.05 or y0 + sy > D - 0.05:
            continue
        if door_s - 0.3 < x0 + sx and x0 < door_s + 1.2 and y0 + sy > D - 1.0:
            continue  # keep the door free
        if layout.fits(x0, y0, x0 + sx, y0 + sy, gap=0.5 if middle else 0.3):
            m = material(b, f"cardboard_{len(b.materials)}", tx.cardboard(rng))
            b.box([x0, y0, 0], [x0 + sx, y0 + sy, sz], m, None)
            layout.add(x0, y0, x0 + sx, y0 + sy)
            placed += 1


def _bin(
    b: SceneBuilder, rng: np.random.Generator, m: _Materials, layout: Layout, cx: float, cy: float
) -> None:
    """A waste bin 1.1 m from the middle of the room, where it fits (100 tries)."""
    for _ in range(100):
        ang = rng.uniform(0, 2 * math.pi)
        bxy = (cx + 1.1 * math.cos(ang), cy + 1.1 * math.sin(ang))
        if layout.fits(bxy[0] - 0.16, bxy[1] - 0.16, bxy[0] + 0.16, bxy[1] + 0.16, 0.5):
            b.prism(bxy, 0.16, 0.0, 0.42, 12, m.bin)
            layout.add(bxy[0] - 0.16, bxy[1] - 0.16, bxy[0] + 0.16, bxy[1] + 0.16)
            return


def _chair(
    b: SceneBuilder, rng: np.random.Generator, m: _Materials, layout: Layout, W: float, D: float
) -> None:
    """A chair on metal legs in the middle part of the room, where it fits (100 tries)."""
    for _ in range(100):
        x0 = float(rng.uniform(1.0, W - 1.5))
        y0 = float(rng.uniform(0.9, D - 1.4))
        if layout.fits(x0, y0, x0 + 0.48, y0 + 0.48, 0.5):
            chair(b, x0, y0, 0.48, "ypos", 0.95, m.fabric, m.steel)
            layout.add(x0, y0, x0 + 0.48, y0 + 0.48)
            return


def office(seed: int) -> SceneMesh:
    """Generate the office scene.

    Args:
        seed: generator seed (``world.seed``); the same seed gives the same scene, textures
            included.

    Returns:
        The scene, with ``start`` set to a free pose near the middle of the room.
    """
    rng = np.random.default_rng(seed)
    W = float(np.round(rng.uniform(5.6, 6.4), 2))
    D = float(np.round(rng.uniform(4.6, 5.4), 2))
    b = SceneBuilder("office")
    m = _office_materials(b, rng)
    walls = _office_walls(W, D)
    _room_shell(b, m, walls, W, D)
    door_s = _wall_decorations(b, rng, m, walls, W, D)

    # Furniture along the walls; the middle of the room stays free for the start pose.
    cx, cy = W / 2, D / 2
    layout = Layout([(cx - 0.5, cy - 0.5, cx + 0.5, cy + 0.5)])
    # Desks: along wall 0 (left part) and wall 3.
    _desk(b, rng, m, layout, 0.15, 0.05, 1.55, 0.75)
    _desk(b, rng, m, layout, 0.05, D - 1.65, 0.75, D - 0.25)
    # Bookcase against wall 2 (right of the door), facing into the room.
    bx = min(W - 1.2, door_s + 1.4 + float(rng.uniform(0, 0.6)))
    bookcase(b, rng, m.dark, (bx, D - 0.38, bx + 0.95, D - 0.02), "yneg")
    layout.add(bx, D - 0.38, bx + 0.95, D - 0.02)
    _filing_cabinet(b, rng, m, layout, W)
    _cardboard_boxes(b, rng, layout, W, D, door_s)
    _bin(b, rng, m, layout, cx, cy)
    _chair(b, rng, m, layout, W, D)

    start = Pose2D(cx, cy, float(rng.uniform(0, 2 * math.pi)))
    return b.build(floor_z=0.0, start=start)
