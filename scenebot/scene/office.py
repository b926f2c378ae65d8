"""The built-in ``office`` scene, generated deterministically from a seed.

A rectangular room (about 6 x 5 x 2.6 m) with carpet, ceiling tiles, painted walls, a door,
a window, posters, a whiteboard (shiny, nearly textureless), a cork board, framed pictures,
desks with metal legs, a bookcase, a metal filing cabinet (shiny), cardboard boxes, and a few
obstacles in the middle (boxes, a bin, a chair). The floor is at z = 0, the room spans
``[0, W] x [0, D]``.
"""

from __future__ import annotations

import math

import numpy as np

from scenebot.robot.base import Pose2D
from scenebot.scene import textures as tx
from scenebot.scene.mesh import Material, SceneBuilder, SceneMesh

ROOM_HEIGHT_M = 2.6


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


def office(seed: int = 7) -> SceneMesh:
    """Generate the office scene.

    Args:
        seed: generator seed; the same seed gives the same scene, textures included.

    Returns:
        The scene, with ``start`` set to a free pose near the middle of the room.
    """
    rng = np.random.default_rng(seed)
    W = float(np.round(rng.uniform(5.6, 6.4), 2))
    D = float(np.round(rng.uniform(4.6, 5.4), 2))
    H = ROOM_HEIGHT_M
    b = SceneBuilder("office")

    def mat(name, texture, **kw) -> int:
        return b.material(Material(name, texture, **kw))

    m_carpet = mat("carpet", tx.carpet(rng, 512))
    m_ceiling = mat("ceiling", tx.ceiling_tiles(rng, 512))
    m_wall = mat("wall_paint", tx.plaster(rng, 256))
    m_base = mat("baseboard", tx.metal(rng, 128, tint=(90, 88, 85)))
    m_wood = mat("desk_wood", tx.wood(rng, 1024, light=True))
    m_dark = mat("dark_wood", tx.wood(rng, 512, light=False))
    m_steel = mat("steel", tx.metal(rng, 256), specular=0.6, shininess=60)
    m_cabinet = mat("cabinet_metal", tx.metal(rng, 256, tint=(150, 160, 170)), specular=0.8)
    m_board = mat("whiteboard", tx.whiteboard(rng), specular=0.9, shininess=120)
    m_cork = mat("cork", tx.cork(rng))
    m_light = mat("ceiling_light", tx.flat((255, 252, 240)), emissive=True)
    m_window = mat("window", tx.framed_picture(rng, 512, 384), emissive=True)
    m_door = mat("door", tx.door(rng))
    m_bin = mat("bin_plastic", tx.flat((45, 48, 52)), specular=0.7, shininess=80)
    m_fabric = mat("chair_fabric", tx.fabric(rng))

    # Room shell.
    b.quad([0, 0, 0], [W, 0, 0], [0, D, 0], m_carpet, uv_size=(0.5, 0.5))
    b.quad([0, 0, H], [0, D, 0], [W, 0, 0], m_ceiling, uv_size=(0.6, 0.6))
    walls = [  # origin, along-wall vector (wall seen from inside: u to the right)
        ([0, 0, 0], [W, 0, 0]),
        ([W, 0, 0], [0, D, 0]),
        ([W, D, 0], [-W, 0, 0]),
        ([0, D, 0], [0, -D, 0]),
    ]
    for o, u in walls:
        b.quad(o, u, [0, 0, H], m_wall, uv_size=(1.0, 1.0))
        n = np.array([-u[1], u[0], 0.0]) / np.linalg.norm(u)
        b.quad(np.array(o) + 0.012 * n, u, [0, 0, 0.08], m_base, uv_size=(0.5, 0.08))
    for lx in (W / 3, 2 * W / 3):
        for ly in (D / 3, 2 * D / 3):
            b.quad([lx - 0.3, ly - 0.3, H - 0.005], [0, 0.6, 0], [0.6, 0, 0], m_light)
            b.light([lx, ly, H - 0.1])

    def on_wall(k: int, s: float, z0: float, w: float, h: float, m: int, off: float = 0.01):
        """A vertical quad on wall k, ``s`` metres along it, bottom at z0."""
        o, u = walls[k]
        u = np.array(u, float)
        length = np.linalg.norm(u)
        t = u / length
        n = np.array([-t[1], t[0], 0.0])
        # seen from inside the room, the texture's u axis runs against the wall direction
        p = np.array(o, float) + (s + w) * t + off * n + [0, 0, z0]
        b.quad(p, -w * t, [0, 0, h], m)

    # Wall decorations: door (wall 2), window (wall 1), whiteboard (wall 0), cork (wall 3).
    wall_len = [W, D, W, D]
    door_s = float(rng.uniform(0.4, 1.0))
    on_wall(2, door_s, 0.0, 0.9, 2.05, m_door)
    on_wall(1, D * 0.5 - 0.8, 0.9, 1.6, 1.1, m_window)
    on_wall(0, W * 0.5 - 0.8, 0.75, 1.6, 0.9, m_board)
    on_wall(3, D * 0.5 - 0.6, 0.7, 1.2, 0.9, m_cork)
    occupied = {0: [(W * 0.5 - 0.8, W * 0.5 + 0.8)], 1: [(D * 0.5 - 0.8, D * 0.5 + 0.8)],
                2: [(door_s, door_s + 0.9)], 3: [(D * 0.5 - 0.6, D * 0.5 + 0.6)]}  # fmt: skip
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
        m = mat(f"{'poster' if is_poster else 'picture'}_{attempt}", tex)
        on_wall(k, s, float(rng.uniform(0.35, 0.9)), w, h, m)
        n_art += 1

    # Furniture along the walls; the middle of the room stays free for the start pose.
    cx, cy = W / 2, D / 2
    layout = _Layout([(cx - 0.5, cy - 0.5, cx + 0.5, cy + 0.5)])

    def desk(x0, y0, x1, y1):
        top = 0.74
        b.box([x0, y0, top - 0.03], [x1, y1, top], {"top": m_wood, "side": m_dark}, (0.8, 0.8))
        for lx, ly in ((x0, y0), (x1 - 0.04, y0), (x0, y1 - 0.04), (x1 - 0.04, y1 - 0.04)):
            b.box([lx, ly, 0], [lx + 0.04, ly + 0.04, top - 0.03], m_steel, (0.1, 0.5))
        # a monitor and a stack of books on top
        mx = x0 + (x1 - x0) * float(rng.uniform(0.25, 0.55))
        my = y0 + (y1 - y0) * 0.5
        b.box([mx, my - 0.05, top], [mx + 0.5, my + 0.05, top + 0.32], m_bin, None)
        bk = mat(f"desk_books_{len(b.materials)}", tx.books(rng, 512, 128))
        b.box([x1 - 0.35, y0 + 0.1, top], [x1 - 0.1, y0 + 0.4, top + 0.12], bk, None)
        layout.add(x0, y0, x1, y1)

    def bookcase(x0, y0, x1, y1, facing):
        h = 1.8
        b.box([x0, y0, 0], [x1, y1, h], m_dark, (0.5, 0.5))
        n_shelves = 5
        for k in range(n_shelves):
            z0 = 0.05 + k * (h - 0.1) / n_shelves
            bk = mat(f"books_{len(b.materials)}", tx.books(rng))
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

    def cardboard_box(x0, y0, sx, sy, sz):
        m = mat(f"cardboard_{len(b.materials)}", tx.cardboard(rng))
        b.box([x0, y0, 0], [x0 + sx, y0 + sy, sz], m, None)
        layout.add(x0, y0, x0 + sx, y0 + sy)

    # Desks: along wall 0 (left part) and wall 3.
    desk(0.15, 0.05, 1.55, 0.75)
    desk(0.05, D - 1.65, 0.75, D - 0.25)
    # Bookcase against wall 2 (right of the door), facing into the room.
    bx = min(W - 1.2, door_s + 1.4 + float(rng.uniform(0, 0.6)))
    bookcase(bx, D - 0.38, bx + 0.95, D - 0.02, "yneg")
    # Filing cabinet against wall 1.
    fy = float(rng.uniform(0.4, 1.0))
    b.box([W - 0.62, fy, 0], [W - 0.02, fy + 0.47, 0.72], m_cabinet, (0.5, 0.35))
    layout.add(W - 0.62, fy, W - 0.02, fy + 0.47)
    # Cardboard boxes along the walls and a few in the middle.
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
            cardboard_box(x0, y0, sx, sy, sz)
            placed += 1
    # A bin and a chair in the middle part of the room.
    for _ in range(100):
        ang = rng.uniform(0, 2 * math.pi)
        bxy = (cx + 1.1 * math.cos(ang), cy + 1.1 * math.sin(ang))
        if layout.fits(bxy[0] - 0.16, bxy[1] - 0.16, bxy[0] + 0.16, bxy[1] + 0.16, 0.5):
            b.prism(bxy, 0.16, 0.0, 0.42, 12, m_bin)
            layout.add(bxy[0] - 0.16, bxy[1] - 0.16, bxy[0] + 0.16, bxy[1] + 0.16)
            break
    for _ in range(100):
        x0 = float(rng.uniform(1.0, W - 1.5))
        y0 = float(rng.uniform(0.9, D - 1.4))
        if layout.fits(x0, y0, x0 + 0.48, y0 + 0.48, 0.5):
            b.box([x0, y0, 0.42], [x0 + 0.48, y0 + 0.48, 0.48], m_fabric, (0.48, 0.48))
            b.box([x0, y0 + 0.42, 0.48], [x0 + 0.48, y0 + 0.48, 0.95], m_fabric, (0.48, 0.48))
            for lx, ly in ((x0, y0), (x0 + 0.45, y0), (x0, y0 + 0.45), (x0 + 0.45, y0 + 0.45)):
                b.box([lx, ly, 0], [lx + 0.03, ly + 0.03, 0.42], m_steel, (0.1, 0.5))
            layout.add(x0, y0, x0 + 0.48, y0 + 0.48)
            break

    start = Pose2D(cx, cy, float(rng.uniform(0, 2 * math.pi)))
    return b.build(floor_z=0.0, start=start)
