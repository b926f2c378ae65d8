"""The built-in ``flat`` scene: two rooms and a corridor, generated deterministically from a seed.

A second world for the evaluation, unlike the office's single open room: a living room and
a bedroom side by side (an interior wall between them), both opening through a doorway onto
a corridor that runs along them. Door leaves stand open beside the doorways, lintels close
the wall above them, and furniture (sofa, coffee table on legs, bookcase, TV stand, bed,
wardrobe, desk and chair, cabinets, boxes, a plant) hides parts of the rooms from most
viewpoints. Textured like the office (:mod:`scenebot.scene.textures`: carpet, parquet, wood,
fabric, books, posters, pictures, cardboard), except that the walls carry patterned
wallpaper (:func:`wallpaper`) rather than plain paint: the rooms are small, so photos often
face a wall from close by, and with plain paint a third of round 0's photos did not register.
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

import numpy as np

from scenebot.robot.base import Pose2D
from scenebot.scene import textures as tx
from scenebot.scene.mesh import Material, SceneBuilder, SceneMesh
from scenebot.scene.office import _Layout

ROOM_HEIGHT_M = 2.5
FLAT_W_M = 8.0  # x extent
FLAT_D_M = 5.0  # y extent
PARTITION_X = (4.0, 4.15)  # wall between the rooms
CORRIDOR_WALL_Y = (3.6, 3.75)  # wall between the rooms and the corridor
DOOR_WIDTH_M = 0.95
LINTEL_Z_M = 2.05


def wallpaper(rng: np.random.Generator, tint, motif, size: int = 512) -> np.ndarray:
    """Patterned wallpaper: a jittered lattice of small motifs over a mottled ground.

    Args:
        rng: generator (the pattern is deterministic from it).
        tint: (3,) ground colour, 0..255.
        motif: (3,) motif colour, 0..255.
        size: texture size (px); the pattern tiles.

    Returns:
        (size, size, 3) uint8.
    """
    import cv2

    ground = np.array(tint, np.float32) * (0.88 + 0.2 * tx.noise(rng, size, 5, 8)[..., None])
    img = ground.copy()
    step = size // 8
    col = tuple(float(c) for c in motif)
    for i in range(8):
        for j in range(8):
            cx = int(j * step + step / 2 + rng.uniform(-0.2, 0.2) * step)
            cy = int(
                i * step + step / 2 + (step / 2 if j % 2 else 0) + rng.uniform(-0.2, 0.2) * step
            )
            kind = int(rng.integers(0, 3))
            r = int(rng.uniform(0.15, 0.3) * step)
            if kind == 0:
                cv2.circle(img, (cx, cy % size), r, col, -1, cv2.LINE_AA)
            elif kind == 1:
                pts = np.array([[cx, cy - r], [cx + r, cy], [cx, cy + r], [cx - r, cy]]) % size
                cv2.fillConvexPoly(img, pts.astype(np.int32), col, cv2.LINE_AA)
            else:
                cv2.ellipse(img, (cx, cy % size), (r, r // 2), float(rng.uniform(0, 180)), 0, 360,
                            col, 2, cv2.LINE_AA)  # fmt: skip
    return np.clip(img, 0, 255).astype(np.uint8)


def flat(seed: int = 7) -> SceneMesh:
    """Generate the two-room flat.

    Args:
        seed: generator seed; the same seed gives the same scene, textures included.

    Returns:
        The scene, with ``start`` set to a free pose in the living room.
    """
    rng = np.random.default_rng(seed)
    W, D, H = FLAT_W_M, FLAT_D_M, ROOM_HEIGHT_M
    px0, px1 = PARTITION_X
    cy0, cy1 = CORRIDOR_WALL_Y
    b = SceneBuilder("flat")

    def mat(name, texture, **kw) -> int:
        return b.material(Material(name, texture, **kw))

    m_carpet = mat("carpet", tx.carpet(rng, 512))
    m_parquet = mat("parquet", tx.wood(rng, 512, light=True))
    m_tiles = mat("corridor_carpet", tx.carpet(rng, 512))
    m_ceiling = mat("ceiling", tx.plaster(rng, 256, tint=(236, 236, 232)))
    m_wall_a = mat("living_wallpaper", wallpaper(rng, (228, 222, 200), (150, 160, 120)))
    m_wall_b = mat("bedroom_wallpaper", wallpaper(rng, (200, 214, 226), (120, 140, 170)))
    m_wall_c = mat("corridor_wallpaper", wallpaper(rng, (226, 220, 200), (160, 120, 80)))
    m_base = mat("baseboard", tx.metal(rng, 128, tint=(235, 235, 230)))
    m_wood = mat("light_wood", tx.wood(rng, 1024, light=True))
    m_dark = mat("dark_wood", tx.wood(rng, 512, light=False))
    m_steel = mat("steel", tx.metal(rng, 256), specular=0.6, shininess=60)
    m_sofa = mat("sofa_fabric", tx.fabric(rng))
    m_bed = mat("bed_fabric", tx.fabric(rng))
    m_door = mat("door", tx.door(rng))
    m_tv = mat("tv_black", tx.flat((30, 32, 36)), specular=0.8, shininess=100)
    m_pot = mat("plant_pot", tx.flat((150, 80, 50)))
    m_leaves = mat("leaves", wallpaper(rng, (70, 115, 55), (35, 75, 30), 256))
    m_light = mat("ceiling_light", tx.flat((255, 252, 240)), emissive=True)
    m_window = mat("window", tx.framed_picture(rng, 512, 384), emissive=True)

    # Floors (one per space) and the ceiling.
    b.quad([0, 0, 0], [px0, 0, 0], [0, cy0, 0], m_carpet, uv_size=(0.5, 0.5))
    b.quad([px1, 0, 0], [W - px1, 0, 0], [0, cy0, 0], m_parquet, uv_size=(0.9, 0.9))
    b.quad([0, cy1, 0], [W, 0, 0], [0, D - cy1, 0], m_tiles, uv_size=(0.5, 0.5))
    b.quad([0, 0, H], [0, D, 0], [W, 0, 0], m_ceiling, uv_size=(1.0, 1.0))

    # Outer walls, painted per space they face, with baseboards.
    def wall(o, u, m):
        b.quad(o, u, [0, 0, H], m, uv_size=(1.0, 1.0))
        u = np.asarray(u, float)
        n = np.array([-u[1], u[0], 0.0]) / np.linalg.norm(u)
        b.quad(np.asarray(o, float) + 0.012 * n, u, [0, 0, 0.08], m_base, uv_size=(0.5, 0.08))

    wall([0, 0, 0], [px0, 0, 0], m_wall_a)  # living room, south
    wall([px1, 0, 0], [W - px1, 0, 0], m_wall_b)  # bedroom, south
    wall([W, 0, 0], [0, cy0, 0], m_wall_b)  # bedroom, east
    wall([W, cy1, 0], [0, D - cy1, 0], m_wall_c)  # corridor, east end
    wall([W, D, 0], [-W, 0, 0], m_wall_c)  # corridor, north
    wall([0, D, 0], [0, cy1 - D, 0], m_wall_c)  # corridor, west end
    wall([0, cy0, 0], [0, -cy0, 0], m_wall_a)  # living room, west

    # Interior walls: solid boxes with doorway gaps and lintels above the doorways.
    door_a = float(np.round(rng.uniform(1.3, 2.2), 2))  # living-room doorway starts here (x)
    door_b = float(np.round(rng.uniform(5.0, 5.9), 2))  # bedroom doorway
    gaps = [(door_a, door_a + DOOR_WIDTH_M), (door_b, door_b + DOOR_WIDTH_M)]
    xs = [0.0, gaps[0][0], gaps[0][1], px0, px1, gaps[1][0], gaps[1][1], W]
    for k in (0, 2, 4, 6):
        x0, x1 = xs[k], xs[k + 1]
        if x1 - x0 > 1e-6:
            m = m_wall_a if x1 <= px0 + 1e-6 else (m_wall_b if x0 >= px0 else m_wall_a)
            b.box([x0, cy0, 0], [x1, cy1, H], {"yneg": m, "ypos": m_wall_c, "side": m},
                  (1.0, 1.0), skip=("bottom", "top"))  # fmt: skip
    b.box([px0, cy0, 0], [px1, cy1, H], m_wall_a, (1.0, 1.0), skip=("bottom", "top"))
    for g0, g1 in gaps:
        b.box([g0, cy0, LINTEL_Z_M], [g1, cy1, H], m_wall_c, (1.0, 1.0), skip=("top",))
    b.box([px0, 0, 0], [px1, cy0, H], {"xneg": m_wall_a, "xpos": m_wall_b, "side": m_wall_a},
          (1.0, 1.0), skip=("bottom", "top"))  # fmt: skip
    for g0, g1 in gaps:  # thresholds: floor under the doorways
        b.quad([g0, cy0, 0], [g1 - g0, 0, 0], [0, cy1 - cy0, 0], m_parquet, uv_size=(0.9, 0.9))
    # Door leaves standing open into each room, hinged at the doorway's west jamb.
    for g0, _ in gaps:
        b.box([g0 + 0.02, cy0 - 0.84, 0.0], [g0 + 0.06, cy0, 2.0], m_door, (0.84, 2.0))

    # Lights: one per room, two in the corridor.
    for lx, ly in ((px0 / 2, cy0 / 2), ((px1 + W) / 2, cy0 / 2), (W / 4, (cy1 + D) / 2),
                   (3 * W / 4, (cy1 + D) / 2)):  # fmt: skip
        b.quad([lx - 0.25, ly - 0.25, H - 0.005], [0, 0.5, 0], [0.5, 0, 0], m_light)
        b.light([lx, ly, H - 0.1])

    # Windows on the outer walls of both rooms (seen from inside: u runs right-to-left).
    b.quad([0.01, 1.4, 0.9], [0, 1.1, 0], [0, 0, 1.1], m_window)  # living room, west wall
    b.quad([W - 0.01, 3.3, 0.9], [0, -1.2, 0], [0, 0, 1.1], m_window)  # bedroom, east wall
    # Posters and pictures: the corridor walls and the rooms.
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
        m = mat(f"{'poster' if is_poster else 'picture'}_{k}", tex)
        s = float(rng.uniform(0.05, 0.2))
        pp = np.array([p0[0] + s * u[0], p0[1] + s * u[1], float(rng.uniform(*zr))])
        pp += 0.01 * np.r_[n, 0]
        uu = np.array([u[0], u[1], 0.0]) * w
        if np.cross(uu, [0, 0, 1])[:2] @ np.asarray(n) < 0:  # keep the image upright, facing n
            pp, uu = pp + uu, -uu
        b.quad(pp, uu, [0, 0, h], m)

    # ------------------------------------------------------------------ living room furniture
    keep = [(door_a - 0.2, cy0 - 1.0, door_a + DOOR_WIDTH_M + 0.2, cy0)]  # doorway approach
    layout = _Layout(keep)
    sx0 = float(rng.uniform(0.4, 0.9))
    b.box([sx0, 0.05, 0], [sx0 + 2.0, 0.95, 0.42], m_sofa, (0.5, 0.5))  # seat
    b.box([sx0, 0.05, 0.42], [sx0 + 2.0, 0.3, 0.85], m_sofa, (0.5, 0.5))  # back
    for ax in (sx0, sx0 + 1.82):
        b.box([ax, 0.3, 0.42], [ax + 0.18, 0.95, 0.62], m_sofa, (0.5, 0.5))  # arms
    layout.add(sx0, 0.05, sx0 + 2.0, 0.95)
    tx0 = sx0 + 0.5
    top = 0.42
    b.box([tx0, 1.35, top - 0.03], [tx0 + 1.0, 1.85, top], {"top": m_wood, "side": m_dark},
          (0.8, 0.8))  # fmt: skip
    for lx, ly in ((tx0, 1.35), (tx0 + 0.96, 1.35), (tx0, 1.81), (tx0 + 0.96, 1.81)):
        b.box([lx, ly, 0], [lx + 0.04, ly + 0.04, top - 0.03], m_steel, (0.1, 0.5))
    layout.add(tx0, 1.35, tx0 + 1.0, 1.85)
    # bookcase against the west wall, facing east
    by0 = float(rng.uniform(0.9, 1.3))
    b.box([0.02, by0, 0], [0.38, by0 + 1.0, 1.9], m_dark, (0.5, 0.5))
    for k in range(5):
        z0 = 0.05 + k * 1.8 / 5
        bk = mat(f"books_{k}", tx.books(rng))
        b.quad([0.384, by0 + 0.02, z0], [0, 0.96, 0], [0, 0, 1.8 / 5 - 0.03], bk)
    layout.add(0.02, by0, 0.38, by0 + 1.0)
    # TV stand and TV against the partition wall, facing west
    ty0 = float(rng.uniform(0.8, 1.4))
    b.box([px0 - 0.45, ty0, 0], [px0 - 0.02, ty0 + 1.3, 0.5], m_wood, (0.6, 0.6))
    b.box([px0 - 0.2, ty0 + 0.1, 0.5], [px0 - 0.12, ty0 + 1.2, 1.15], m_tv, None)
    layout.add(px0 - 0.45, ty0, px0 - 0.02, ty0 + 1.3)
    # a plant in the south-east corner
    b.prism((px0 - 0.3, 0.3), 0.18, 0.0, 0.4, 10, m_pot)
    b.prism((px0 - 0.3, 0.3), 0.3, 0.4, 1.2, 8, m_leaves)
    layout.add(px0 - 0.6, 0.0, px0, 0.6)

    # --------------------------------------------------------------------- bedroom furniture
    blayout = _Layout([(door_b - 0.2, cy0 - 1.0, door_b + DOOR_WIDTH_M + 0.2, cy0)])
    bedy = float(rng.uniform(0.3, 0.8))
    b.box([W - 2.05, bedy, 0], [W - 0.05, bedy + 1.6, 0.55], m_bed, (0.8, 0.8))
    b.box([W - 0.12, bedy, 0.55], [W - 0.02, bedy + 1.6, 1.1], m_dark, (0.5, 0.5))
    blayout.add(W - 2.05, bedy, W - 0.02, bedy + 1.6)
    b.box([W - 0.5, bedy + 1.7, 0], [W - 0.05, bedy + 2.1, 0.5], m_wood, (0.4, 0.4))  # nightstand
    blayout.add(W - 0.5, bedy + 1.7, W - 0.05, bedy + 2.1)
    wx0 = px1 + float(rng.uniform(0.05, 0.4))
    b.box([wx0, 0.02, 0], [wx0 + 1.2, 0.62, 2.0], {"ypos": m_wood, "side": m_dark}, (0.6, 1.0))
    blayout.add(wx0, 0.02, wx0 + 1.2, 0.62)
    # desk with a chair against the partition, north of the wardrobe
    dy0 = float(rng.uniform(1.6, 2.1))
    dtop = 0.74
    desk_mats = {"top": m_wood, "side": m_dark}
    b.box([px1 + 0.02, dy0, dtop - 0.03], [px1 + 0.7, dy0 + 1.2, dtop], desk_mats, (0.8, 0.8))
    for lx, ly in ((px1 + 0.02, dy0), (px1 + 0.66, dy0), (px1 + 0.02, dy0 + 1.16),
                   (px1 + 0.66, dy0 + 1.16)):  # fmt: skip
        b.box([lx, ly, 0], [lx + 0.04, ly + 0.04, dtop - 0.03], m_steel, (0.1, 0.5))
    bk = mat("desk_books", tx.books(rng, 512, 128))
    b.box([px1 + 0.1, dy0 + 0.8, dtop], [px1 + 0.4, dy0 + 1.1, dtop + 0.14], bk, None)
    blayout.add(px1 + 0.02, dy0, px1 + 0.7, dy0 + 1.2)
    cx0 = px1 + 0.85
    cy = dy0 + 0.35
    b.box([cx0, cy, 0.42], [cx0 + 0.46, cy + 0.46, 0.48], m_sofa, (0.46, 0.46))
    b.box([cx0 + 0.4, cy, 0.48], [cx0 + 0.46, cy + 0.46, 0.92], m_sofa, (0.46, 0.46))
    for lx, ly in ((cx0, cy), (cx0 + 0.43, cy), (cx0, cy + 0.43), (cx0 + 0.43, cy + 0.43)):
        b.box([lx, ly, 0], [lx + 0.03, ly + 0.03, 0.42], m_steel, (0.1, 0.5))
    blayout.add(cx0, cy, cx0 + 0.46, cy + 0.46)

    # ---------------------------------------------------------------------- corridor and boxes
    kx0 = float(rng.uniform(0.3, 1.0))
    b.box([kx0, D - 0.36, 0], [kx0 + 1.1, D - 0.02, 0.9], {"yneg": m_wood, "side": m_dark},
          (0.55, 0.45))  # fmt: skip
    sx = float(rng.uniform(4.6, 6.0))
    b.box([sx, D - 0.4, 0], [sx + 1.3, D - 0.02, 0.8], {"yneg": m_dark, "side": m_wood},
          (0.65, 0.4))  # fmt: skip
    vase = mat("vase", tx.flat((60, 90, 140)), specular=0.5)
    b.prism((sx + 0.3, D - 0.21), 0.08, 0.8, 1.1, 10, vase)

    def boxes(lay: _Layout, x_rng, y_rng, n):
        placed = 0
        for _ in range(200):
            if placed >= n:
                return
            sx_, sy_ = rng.uniform(0.3, 0.55, 2)
            sz = float(rng.uniform(0.25, 0.5))
            x0, y0 = rng.uniform(x_rng[0], x_rng[1] - sx_), rng.uniform(y_rng[0], y_rng[1] - sy_)
            if lay.fits(x0, y0, x0 + sx_, y0 + sy_, gap=0.55):
                m = mat(f"cardboard_{len(b.materials)}", tx.cardboard(rng))
                b.box([x0, y0, 0], [x0 + sx_, y0 + sy_, sz], m, None)
                lay.add(x0, y0, x0 + sx_, y0 + sy_)
                placed += 1

    start_xy = (tx0 + 1.5, 2.5)
    layout.add(start_xy[0] - 0.5, start_xy[1] - 0.5, start_xy[0] + 0.5, start_xy[1] + 0.5)
    boxes(layout, (0.05, px0 - 0.05), (0.05, cy0 - 0.05), 2)
    boxes(blayout, (px1 + 0.05, W - 0.05), (0.05, cy0 - 0.05), 2)
    theta = float(rng.uniform(0, 2 * math.pi))
    return b.build(floor_z=0.0, start=Pose2D(start_xy[0], start_xy[1], theta))
