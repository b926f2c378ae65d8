"""Parts the built-in scenes share: walls, wall decorations, furniture, and their layout.

Every builder adds textured quads, boxes and prisms to a
:class:`~scenebot.scene.mesh.SceneBuilder`; coordinates are metres in the world frame (floor
at z = 0, z up). Furniture on legs (tables, desks, chairs, a bed's frame) leaves the floor
under it free between thin legs: the robot (0.40 m tall) drives under a top whose underside
is higher, so the simulator's collision map holds only the legs. A builder that draws random
numbers does so in a fixed order: the scenes' seeds depend on it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scenebot.scene import textures as tx
from scenebot.scene.mesh import Material, SceneBuilder

Rect = tuple[float, float, float, float]
"""A floor rectangle ``(x0, y0, x1, y1)`` (m), x0 <= x1 and y0 <= y1."""

Wall = tuple[list[float], list[float]]
"""A wall: origin and along-wall vector (m); the room lies to the left of the vector."""

LEG_M = 0.04
"""Side of a table leg's square section (m)."""


class Layout:
    """Keeps floor rectangles of placed furniture (and of spots kept free) apart.

    Args:
        keep_free: rectangles nothing may be placed near (the start pose, doorways).
    """

    def __init__(self, keep_free: list[Rect]):
        self.rects = list(keep_free)

    def fits(self, x0, y0, x1, y1, gap=0.35) -> bool:
        """Whether the rectangle stays ``gap`` m or more away from every one held."""
        for a0, b0, a1, b1 in self.rects:
            if x0 < a1 + gap and a0 < x1 + gap and y0 < b1 + gap and b0 < y1 + gap:
                return False
        return True

    def add(self, x0, y0, x1, y1) -> None:
        """Hold the rectangle ``(x0, y0)``-``(x1, y1)``."""
        self.rects.append((x0, y0, x1, y1))


def material(b: SceneBuilder, name: str, texture: np.ndarray, **kw) -> int:
    """Register a material named ``name`` with ``texture`` (and Material's ``kw``)."""
    return b.material(Material(name, texture, **kw))


# ------------------------------------------------------------------------------------ walls
def wall_with_baseboard(b: SceneBuilder, o, u, height: float, paper: int, base: int) -> None:
    """A wall quad from ``o`` along ``u`` (room on its left), ``height`` m high, and an 8 cm
    baseboard 12 mm in front of it."""
    b.quad(o, u, [0, 0, height], paper, uv_size=(1.0, 1.0))
    u = np.asarray(u, float)
    n = np.array([-u[1], u[0], 0.0]) / np.linalg.norm(u)
    b.quad(np.asarray(o, float) + 0.012 * n, u, [0, 0, 0.08], base, uv_size=(0.5, 0.08))


@dataclass
class HomeMaterials:
    """Indices in the builder of the materials every home scene shares
    (:func:`home_materials`, :func:`home_fittings`); a scene's own materials subclass it."""

    base: int
    wood: int
    dark: int
    steel: int
    door: int
    tv: int
    pot: int
    leaves: int
    light: int
    window: int


def home_materials(b: SceneBuilder, rng: np.random.Generator) -> dict[str, int]:
    """The materials every home scene's furniture shares, drawn from ``rng`` in this order:
    ``base`` (white baseboard), ``wood`` (light wood), ``dark`` (dark wood), ``steel``."""
    return {
        "base": material(b, "baseboard", tx.metal(rng, 128, tint=(235, 235, 230))),
        "wood": material(b, "light_wood", tx.wood(rng, 1024, light=True)),
        "dark": material(b, "dark_wood", tx.wood(rng, 512, light=False)),
        "steel": material(b, "steel", tx.metal(rng, 256), specular=0.6, shininess=60),
    }


def home_fittings(b: SceneBuilder, rng: np.random.Generator) -> dict[str, int]:
    """The fittings every home scene shares, drawn from ``rng`` in this order: ``door``,
    ``tv`` (black gloss), ``pot`` and ``leaves`` (a plant), ``light`` (ceiling lamps),
    ``window`` (a landscape picture, emissive)."""
    return {
        "door": material(b, "door", tx.door(rng)),
        "tv": material(b, "tv_black", tx.flat((30, 32, 36)), specular=0.8, shininess=100),
        "pot": material(b, "plant_pot", tx.flat((150, 80, 50))),
        "leaves": material(b, "leaves", tx.wallpaper(rng, (70, 115, 55), (35, 75, 30), 256)),
        "light": material(b, "ceiling_light", tx.flat((255, 252, 240)), emissive=True),
        "window": material(b, "window", tx.framed_picture(rng, 512, 384), emissive=True),
    }


def on_wall(
    b: SceneBuilder, wall: Wall, s: float, z0: float, w: float, h: float, m: int, off: float = 0.01
) -> None:
    """A ``w`` x ``h`` m picture (material ``m``) on ``wall``, ``s`` m along it, bottom at z0,
    ``off`` m in front of the wall; upright and unmirrored as seen from the room."""
    o, u = wall
    u = np.array(u, float)
    length = np.linalg.norm(u)
    t = u / length
    n = np.array([-t[1], t[0], 0.0])
    # seen from inside the room, the texture's u axis runs against the wall direction
    p = np.array(o, float) + (s + w) * t + off * n + [0, 0, z0]
    b.quad(p, -w * t, [0, 0, h], m)


def wall_art(
    b: SceneBuilder,
    rng: np.random.Generator,
    walls: list[Wall],
    wall_len: list[float],
    occupied: dict[int, list[tuple[float, float]]],
    n_max: int = 9,
    tag: str = "",
) -> int:
    """Up to ``n_max`` posters and framed pictures at random free spots of the walls (60 tries).

    Args:
        b: the builder.
        rng: generator.
        walls: the walls to hang them on.
        wall_len: each wall's length (m).
        occupied: per wall index, the stretches ``(s0, s1)`` (m along it) already taken
            (doors, windows, boards); the new pictures are added.
        n_max: most pictures to hang.
        tag: put into the materials' names (``poster_<tag><try>``), unique per call.

    Returns:
        How many were hung.
    """
    n_art = 0
    for attempt in range(60):
        if n_art >= n_max:
            break
        k = int(rng.integers(0, len(walls)))
        is_poster = rng.random() < 0.65
        w = float(rng.uniform(0.45, 0.7)) if is_poster else float(rng.uniform(0.5, 0.8))
        h = w * (1.4 if is_poster else 0.75)
        s = float(rng.uniform(0.25, max(wall_len[k] - w - 0.25, 0.25)))
        if s + w > wall_len[k] - 0.25 or any(
            s < e + 0.15 and a < s + w + 0.15 for a, e in occupied[k]
        ):
            continue
        occupied[k].append((s, s + w))
        tex = tx.poster(rng) if is_poster else tx.framed_picture(rng)
        m = material(b, f"{'poster' if is_poster else 'picture'}_{tag}{attempt}", tex)
        on_wall(b, walls[k], s, float(rng.uniform(0.35, 0.9)), w, h, m)
        n_art += 1
    return n_art


# -------------------------------------------------------------------------------- furniture
def table_on_legs(b: SceneBuilder, rect: Rect, top_z: float, top: dict[str, int], steel: int):
    """A 3 cm table top at ``top_z`` m over ``rect`` on four 4 cm steel legs at its corners.

    Args:
        b: the builder.
        rect: the top's floor rectangle (m).
        top_z: height of the top's upper face (m).
        top: the top's materials (``{"top": ..., "side": ...}``).
        steel: the legs' material.
    """
    x0, y0, x1, y1 = rect
    b.box([x0, y0, top_z - 0.03], [x1, y1, top_z], top, (0.8, 0.8))
    for lx, ly in ((x0, y0), (x1 - LEG_M, y0), (x0, y1 - LEG_M), (x1 - LEG_M, y1 - LEG_M)):
        b.box([lx, ly, 0], [lx + LEG_M, ly + LEG_M, top_z - 0.03], steel, (0.1, 0.5))


def chair(
    b: SceneBuilder, x0: float, y0: float, size: float, back: str, back_z: float, fabric, steel
) -> None:
    """A chair on 3 cm steel legs: a ``size`` m square seat at 0.42-0.48 m, ``(x0, y0)`` its
    south-west corner, and a 6 cm back on side ``back`` (``"xpos"``, ``"ypos"``, ...) up to
    ``back_z`` m. The seat is above the robot: it drives under the chair, between the legs."""
    x1, y1 = x0 + size, y0 + size
    b.box([x0, y0, 0.42], [x1, y1, 0.48], fabric, (size, size))
    bx0, by0, bx1, by1 = strip((x0, y0, x1, y1), back, 0.06)
    b.box([bx0, by0, 0.48], [bx1, by1, back_z], fabric, (size, size))
    for lx, ly in ((x0, y0), (x1 - 0.03, y0), (x0, y1 - 0.03), (x1 - 0.03, y1 - 0.03)):
        b.box([lx, ly, 0], [lx + 0.03, ly + 0.03, 0.42], steel, (0.1, 0.5))


def bookcase(
    b: SceneBuilder,
    rng: np.random.Generator,
    wood: int,
    rect: Rect,
    facing: str,
    height: float = 1.8,
    name: str = "books_{n}",
) -> None:
    """A bookcase over ``rect``, ``height`` m tall, five shelves of books on its ``facing``
    side (``"xpos"``, ``"xneg"``, ``"ypos"`` or ``"yneg"``); each shelf's book texture is
    named ``name`` formatted with ``k`` (the shelf) and ``n`` (the materials so far)."""
    x0, y0, x1, y1 = rect
    b.box([x0, y0, 0], [x1, y1, height], wood, (0.5, 0.5))
    n_shelves = 5
    for k in range(n_shelves):
        z0 = 0.05 + k * (height - 0.1) / n_shelves
        bk = material(b, name.format(k=k, n=len(b.materials)), tx.books(rng))
        hh = (height - 0.1) / n_shelves - 0.03
        if facing == "ypos":
            b.quad([x1 - 0.02, y1 + 0.004, z0], [-(x1 - x0 - 0.04), 0, 0], [0, 0, hh], bk)
        elif facing == "yneg":
            b.quad([x0 + 0.02, y0 - 0.004, z0], [x1 - x0 - 0.04, 0, 0], [0, 0, hh], bk)
        elif facing == "xpos":
            b.quad([x1 + 0.004, y0 + 0.02, z0], [0, y1 - y0 - 0.04, 0], [0, 0, hh], bk)
        else:
            b.quad([x0 - 0.004, y1 - 0.02, z0], [0, -(y1 - y0 - 0.04), 0], [0, 0, hh], bk)


def strip(rect: Rect, side: str, depth: float) -> Rect:
    """The ``depth`` m wide strip of ``rect`` along its side ``side`` (``"xneg"``, ...)."""
    x0, y0, x1, y1 = rect
    return {
        "xneg": (x0, y0, x0 + depth, y1),
        "xpos": (x1 - depth, y0, x1, y1),
        "yneg": (x0, y0, x1, y0 + depth),
        "ypos": (x0, y1 - depth, x1, y1),
    }[side]


def _box2(b: SceneBuilder, rect: Rect, z0: float, z1: float, m, uv=(0.5, 0.5)) -> None:
    """A box over the floor rectangle ``rect`` from height z0 to z1 (m)."""
    b.box([rect[0], rect[1], z0], [rect[2], rect[3], z1], m, uv)


def sofa(b: SceneBuilder, rect: Rect, back: str, fabric: int) -> None:
    """A sofa over ``rect``: a seat up to 0.42 m, a 25 cm back on side ``back`` up to 0.85 m
    and 18 cm arms at both ends up to 0.62 m."""
    _box2(b, rect, 0.0, 0.42, fabric)  # seat
    back_rect = strip(rect, back, 0.25)
    _box2(b, back_rect, 0.42, 0.85, fabric)
    x0, y0, x1, y1 = rect
    bx0, by0, bx1, by1 = back_rect
    front = {"xneg": (bx1, y0, x1, y1), "xpos": (x0, y0, bx0, y1),
             "yneg": (x0, by1, x1, y1), "ypos": (x0, y0, x1, by0)}[back]  # fmt: skip
    for end in ("xneg", "xpos") if back[0] == "y" else ("yneg", "ypos"):
        _box2(b, strip(front, end, 0.18), 0.42, 0.62, fabric)  # arms


def plant(b: SceneBuilder, center, pot: int, leaves: int) -> None:
    """A potted plant at ``center`` (x, y): a 0.4 m pot and foliage up to 1.2 m."""
    b.prism(center, 0.18, 0.0, 0.4, 10, pot)
    b.prism(center, 0.3, 0.4, 1.2, 8, leaves)


def boxes(b: SceneBuilder, rng: np.random.Generator, lay: Layout, x_rng, y_rng, n: int, gap=0.55):
    """Up to ``n`` cardboard boxes at random free spots of ``x_rng`` x ``y_rng`` (m; 200 tries),
    ``gap`` m from everything ``lay`` holds.

    Returns:
        The boxes placed, as ``(rect, height)``.
    """
    placed: list[tuple[Rect, float]] = []
    for _ in range(200):
        if len(placed) >= n:
            break
        sx_, sy_ = rng.uniform(0.3, 0.55, 2)
        sz = float(rng.uniform(0.25, 0.5))
        x0, y0 = rng.uniform(x_rng[0], x_rng[1] - sx_), rng.uniform(y_rng[0], y_rng[1] - sy_)
        if lay.fits(x0, y0, x0 + sx_, y0 + sy_, gap=gap):
            m = material(b, f"cardboard_{len(b.materials)}", tx.cardboard(rng))
            b.box([x0, y0, 0], [x0 + sx_, y0 + sy_, sz], m, None)
            lay.add(x0, y0, x0 + sx_, y0 + sy_)
            placed.append(((float(x0), float(y0), float(x0 + sx_), float(y0 + sy_)), sz))
    return placed


def bed(b: SceneBuilder, rect: Rect, head: str, under_z: float, frame: int, cover: int) -> None:
    """A bed over ``rect`` with its headboard on side ``head``, on legs: frame and mattress
    from ``under_z`` m (0.45 leaves room for the robot underneath) to ``under_z`` + 0.32 m,
    an 8 cm headboard from the floor to 1 m, and two 5 cm legs at the foot."""
    x0, y0, x1, y1 = rect
    hx0, hy0, hx1, hy1 = strip(rect, head, 0.08)
    body = {"xneg": (hx1, y0, x1, y1), "xpos": (x0, y0, hx0, y1),
            "yneg": (x0, hy1, x1, y1), "ypos": (x0, y0, x1, hy0)}[head]  # fmt: skip
    _box2(b, (hx0, hy0, hx1, hy1), 0.0, 1.0, frame)
    _box2(b, body, under_z, under_z + 0.12, frame)
    _box2(b, body, under_z + 0.12, under_z + 0.32, cover, (0.8, 0.8))
    foot = strip(body, {"xneg": "xpos", "xpos": "xneg", "yneg": "ypos", "ypos": "yneg"}[head], 0.05)
    ends = ("xneg", "xpos") if head[0] == "y" else ("yneg", "ypos")
    for end in ends:
        _box2(b, strip(foot, end, 0.05), 0.0, under_z, frame, (0.1, 0.5))


def cabinet(b: SceneBuilder, rect: Rect, height: float, front: str, door: int, body: int):
    """A closed cabinet (sideboard, wardrobe) over ``rect``, ``height`` m tall: its front
    (side ``front``) shows the texture ``door`` once (doors and handles, see
    :func:`~scenebot.scene.textures.cabinet_front`), the rest is ``body``."""
    _box2(b, rect, 0.0, height, {front: door, "side": body}, None)
