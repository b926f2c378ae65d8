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
from scenebot.scene.mesh import Material, SceneBuilder, SceneMesh

ROOM_HEIGHT_M = 2.6

_Wall = tuple[list[float], list[float]]
"""A wall: origin and along-wall vector (seen from inside the room, u runs to the right)."""


class _Layout:
    """Keeps floor rectangles of placed furniture apart."""

    def __init__(self, keep_free: list[tuple[float, float, float, float]]):
        self.rects = list(keep_free)

    def fits(self, x0, y0, x1, y1, gap=0.35) -> bool:
        for a0, b0, a1, b1 in self.rects:
            if x0 < a1 + gap and a0 < x1 + gap and y0 < b1 + gap and b0 < y1 + gap:
                return False
        return True

    def add(self, x0, y0, x1, y1) -> None:
        self.rects.append((x0, y0, x1, y1))


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


def _material(b: SceneBuilder, name: str, texture: np.ndarray, **kw) -> int:
    return b.material(Material(name, texture, **kw))


def _office_materials(b: SceneBuilder, rng: np.random.Generator) -> _Materials:
    """The fixed materials, their textures drawn in this order."""
    return _Materials(
        carpet=_material(b, "carpet", tx.carpet(rng, 512)),
        ceiling=_material(b, "ceiling", tx.ceiling_tiles(rng, 512)),
        wall=_material(b, "wall_paint", tx.plaster(rng, 256)),
        base=_material(b, "baseboard", tx.metal(rng, 128, tint=(90, 88, 85))),
        wood=_material(b, "desk_wood", tx.wood(rng, 1024, light=True)),
        dark=_material(b, "dark_wood", tx.wood(rng, 512, light=False)),
        steel=_material(b, "steel", tx.metal(rng, 256), specular=0.6, shininess=60),
        cabinet=_material(
            b, "cabinet_metal", tx.metal(rng, 256, tint=(150, 160, 170)), specular=0.8
        ),
        board=_material(b, "whiteboard", tx.whiteboard(rng), specular=0.9, shininess=120),
        cork=_material(b, "cork", tx.cork(rng)),
        light=_material(b, "ceiling_light", tx.flat((255, 252, 240)), emissive=True),
        window=_material(b, "window", tx.framed_picture(rng, 512, 384), emissive=True),
        door=_material(b, "door", tx.door(rng)),
        bin=_material(b, "bin_plastic", tx.flat((45, 48, 52)), specular=0.7, shininess=80),
        fabric=_material(b, "chair_fabric", tx.fabric(rng)),
    )


def _office_walls(W: float, D: float) -> list[_Wall]:
    """The four walls, numbered 0..3 counter-clockwise from the one along y = 0."""
    return [
        ([0, 0, 0], [W, 0, 0]),
        ([W, 0, 0], [0, D, 0]),
        ([W, D, 0], [-W, 0, 0]),
        ([0, D, 0], [0, -D, 0]),
    ]


def _room_shell(b: SceneBuilder, m: _Materials, walls: list[_Wall], W: float, D: float) -> None:
    """Floor, ceiling, painted walls with baseboards, and four ceiling lights."""
    H = ROOM_HEIGHT_M
    b.quad([0, 0, 0], [W, 0, 0], [0, D, 0], m.carpet, uv_size=(0.5, 0.5))
    b.quad([0, 0, H], [0, D, 0], [W, 0, 0], m.ceiling, uv_size=(0.6, 0.6))
    for o, u in walls:
        b.quad(o, u, [0, 0, H], m.wall, uv_size=(1.0, 1.0))
        n = np.array([-u[1], u[0], 0.0]) / np.linalg.norm(u)
        b.quad(np.array(o) + 0.012 * n, u, [0, 0, 0.08], m.base, uv_size=(0.5, 0.08))
    for lx in (W / 3, 2 * W / 3):
        for ly in (D / 3, 2 * D / 3):
            b.quad([lx - 0.3, ly - 0.3, H - 0.005], [0, 0.6, 0], [0.6, 0, 0], m.light)
            b.light([lx, ly, H - 0.1])


def _on_wall(
    b: SceneBuilder, wall: _Wall, s: float, z0: float, w: float, h: float, m: int, off: float = 0.01
) -> None:
    """A vertical quad on ``wall``, ``s`` metres along it, bottom at z0."""
    o, u = wall
    u = np.array(u, float)
    length = np.linalg.norm(u)
    t = u / length
    n = np.array([-t[1], t[0], 0.0])
    # seen from inside the room, the texture's u axis runs against the wall direction
    p = np.array(o, float) + (s + w) * t + off * n + [0, 0, z0]
    b.quad(p, -w * t, [0, 0, h], m)


def _wall_decorations(
    b: SceneBuilder, rng: np.random.Generator, m: _Materials, walls: list[_Wall], W: float, D: float
) -> float:
    """Door (wall 2), window (wall 1), whiteboard (wall 0), cork (wall 3), then the art.

    Returns:
        Where the door starts along wall 2 (m).
    """
    door_s = float(rng.uniform(0.4, 1.0))
    _on_wall(b, walls[2], door_s, 0.0, 0.9, 2.05, m.door)
    _on_wall(b, walls[1], D * 0.5 - 0.8, 0.9, 1.6, 1.1, m.window)
    _on_wall(b, walls[0], W * 0.5 - 0.8, 0.75, 1.6, 0.9, m.board)
    _on_wall(b, walls[3], D * 0.5 - 0.6, 0.7, 1.2, 0.9, m.cork)
    occupied = {0: [(W * 0.5 - 0.8, W * 0.5 + 0.8)], 1: [(D * 0.5 - 0.8, D * 0.5 + 0.8)],
                2: [(door_s, door_s + 0.9)], 3: [(D * 0.5 - 0.6, D * 0.5 + 0.6)]}  # fmt: skip
    _wall_art(b, rng, walls, [W, D, W, D], occupied)
    return door_s


def _wall_art(
    b: SceneBuilder,
    rng: np.random.Generator,
    walls: list[_Wall],
    wall_len: list[float],
    occupied: dict[int, list[tuple[float, float]]],
) -> None:
    """Up to 9 posters and framed pictures at random free spots of the walls (60 tries)."""
    n_art = 0
    for attempt in range(60):
        if n_art >= 9:
            break
        k = int(rng.integers(0, 4))
        is_poster = rng.random() < 0.65
        w = float(rng.uniform(0.45, 0.7)) if is_poster else float(rng.uniform(0.5, 0.8))
        h = w * (1.4 if is_poster else 0.75)
        s = float(rng.uniform(0.25, wall_len[k] - w - 0.25))
        if any(s < e + 0.15 and a < s + w + 0.15 for a, e in occupied[k]):
            continue
        occupied[k].append((s, s + w))
        tex = tx.poster(rng) if is_poster else tx.framed_picture(rng)
        m = _material(b, f"{'poster' if is_poster else 'picture'}_{attempt}", tex)
        _on_wall(b, walls[k], s, float(rng.uniform(0.35, 0.9)), w, h, m)
        n_art += 1


def _desk(
    b: SceneBuilder,
    rng: np.random.Generator,
    m: _Materials,
    layout: _Layout,
    x0: float,
    y0: float,
    x1: float,
    y1: float,
) -> None:
    """A desk on metal legs with a monitor and a stack of books on top."""
    top = 0.74
    b.box([x0, y0, top - 0.03], [x1, y1, top], {"top": m.wood, "side": m.dark}, (0.8, 0.8))
    for lx, ly in ((x0, y0), (x1 - 0.04, y0), (x0, y1 - 0.04), (x1 - 0.04, y1 - 0.04)):
        b.box([lx, ly, 0], [lx + 0.04, ly + 0.04, top - 0.03], m.steel, (0.1, 0.5))
    mx = x0 + (x1 - x0) * float(rng.uniform(0.25, 0.55))
    my = y0 + (y1 - y0) * 0.5
    b.box([mx, my - 0.05, top], [mx + 0.5, my + 0.05, top + 0.32], m.bin, None)
    bk = _material(b, f"desk_books_{len(b.materials)}", tx.books(rng, 512, 128))
    b.box([x1 - 0.35, y0 + 0.1, top], [x1 - 0.1, y0 + 0.4, top + 0.12], bk, None)
    layout.add(x0, y0, x1, y1)


def _bookcase(
    b: SceneBuilder,
    rng: np.random.Generator,
    m: _Materials,
    layout: _Layout,
    x0: float,
    y0: float,
    x1: float,
    y1: float,
    facing: str,
) -> None:
    """A bookcase with five shelves of books on its ``facing`` side."""
    h = 1.8
    b.box([x0, y0, 0], [x1, y1, h], m.dark, (0.5, 0.5))
    n_shelves = 5
    for k in range(n_shelves):
        z0 = 0.05 + k * (h - 0.1) / n_shelves
        bk = _material(b, f"books_{len(b.materials)}", tx.books(rng))
        hh = (h - 0.1) / n_shelves - 0.03
        if facing == "ypos":
            b.quad([x1 - 0.02, y1 + 0.004, z0], [-(x1 - x0 - 0.04), 0, 0], [0, 0, hh], bk)
        elif facing == "yneg":
            b.quad([x0 + 0.02, y0 - 0.004, z0], [x1 - x0 - 0.04, 0, 0], [0, 0, hh], bk)
        elif facing == "xpos":
            b.quad([x1 + 0.004, y0 + 0.02, z0], [0, y1 - y0 - 0.04, 0], [0, 0, hh], bk)
        else:
            b.quad([x0 - 0.004, y1 - 0.02, z0], [0, -(y1 - y0 - 0.04), 0], [0, 0, hh], bk)
    layout.add(x0, y0, x1, y1)


def _filing_cabinet(
    b: SceneBuilder, rng: np.random.Generator, m: _Materials, layout: _Layout, W: float
) -> None:
    """A metal filing cabinet against wall 1."""
    fy = float(rng.uniform(0.4, 1.0))
    b.box([W - 0.62, fy, 0], [W - 0.02, fy + 0.47, 0.72], m.cabinet, (0.5, 0.35))
    layout.add(W - 0.62, fy, W - 0.02, fy + 0.47)


def _cardboard_boxes(
    b: SceneBuilder, rng: np.random.Generator, layout: _Layout, W: float, D: float, door_s: float
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
            m = _material(b, f"cardboard_{len(b.materials)}", tx.cardboard(rng))
            b.box([x0, y0, 0], [x0 + sx, y0 + sy, sz], m, None)
            layout.add(x0, y0, x0 + sx, y0 + sy)
            placed += 1


def _bin(
    b: SceneBuilder, rng: np.random.Generator, m: _Materials, layout: _Layout, cx: float, cy: float
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
    b: SceneBuilder, rng: np.random.Generator, m: _Materials, layout: _Layout, W: float, D: float
) -> None:
    """A chair on metal legs in the middle part of the room, where it fits (100 tries)."""
    for _ in range(100):
        x0 = float(rng.uniform(1.0, W - 1.5))
        y0 = float(rng.uniform(0.9, D - 1.4))
        if layout.fits(x0, y0, x0 + 0.48, y0 + 0.48, 0.5):
            b.box([x0, y0, 0.42], [x0 + 0.48, y0 + 0.48, 0.48], m.fabric, (0.48, 0.48))
            b.box([x0, y0 + 0.42, 0.48], [x0 + 0.48, y0 + 0.48, 0.95], m.fabric, (0.48, 0.48))
            for lx, ly in ((x0, y0), (x0 + 0.45, y0), (x0, y0 + 0.45), (x0 + 0.45, y0 + 0.45)):
                b.box([lx, ly, 0], [lx + 0.03, ly + 0.03, 0.42], m.steel, (0.1, 0.5))
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
    layout = _Layout([(cx - 0.5, cy - 0.5, cx + 0.5, cy + 0.5)])
    # Desks: along wall 0 (left part) and wall 3.
    _desk(b, rng, m, layout, 0.15, 0.05, 1.55, 0.75)
    _desk(b, rng, m, layout, 0.05, D - 1.65, 0.75, D - 0.25)
    # Bookcase against wall 2 (right of the door), facing into the room.
    bx = min(W - 1.2, door_s + 1.4 + float(rng.uniform(0, 0.6)))
    _bookcase(b, rng, m, layout, bx, D - 0.38, bx + 0.95, D - 0.02, "yneg")
    _filing_cabinet(b, rng, m, layout, W)
    _cardboard_boxes(b, rng, layout, W, D, door_s)
    _bin(b, rng, m, layout, cx, cy)
    _chair(b, rng, m, layout, W, D)

    start = Pose2D(cx, cy, float(rng.uniform(0, 2 * math.pi)))
    return b.build(floor_z=0.0, start=start)
