"""Procedural textures for the built-in scenes, deterministic from a numpy Generator.

Each function returns an (H, W, 3) uint8 sRGB image. They imitate what a room offers a
feature detector: rich (carpet, wood grain, posters, book spines, cork boards, printed
cardboard), poor (painted walls, whiteboards, metal) and repeating (wallpaper, tiles,
parquet: the same pattern every few decimetres, which matching can confuse).
"""

from __future__ import annotations

import cv2
import numpy as np

# fmt: off
_WORDS = (
    "SCENE", "ROBOT", "LAB", "OFFICE", "MEETING", "PROJECT", "DATA", "VISION", "LIGHT",
    "FIELD", "CAMERA", "GRAPH", "MODEL", "NOTES", "PLAN", "BUDGET", "REVIEW", "SPRING",
    "AUTUMN", "HELLO", "SAFETY", "EXIT", "LUMIGRAPH", "STEREO", "SIFT", "BUNDLE", "MAP",
    "PATH", "GOAL", "KERNEL", "TEAM", "COFFEE", "PRINTER", "REPORT", "WEEKLY", "SEMINAR",
    "2026", "ROOM",
)
# fmt: on


def noise(rng: np.random.Generator, size: int, octaves: int = 5, base: int = 4) -> np.ndarray:
    """Multi-octave value noise in [0, 1], shape (size, size), tileable-ish."""
    out = np.zeros((size, size), np.float32)
    amp, total = 1.0, 0.0
    cells = base
    for _ in range(octaves):
        grid = rng.random((cells, cells)).astype(np.float32)
        grid = np.pad(grid, 2, mode="wrap")
        up = cv2.resize(grid, (size + size * 4 // cells, size + size * 4 // cells), cv2.INTER_CUBIC)
        off = size * 2 // cells
        out += amp * up[off : off + size, off : off + size]
        total += amp
        amp *= 0.5
        cells *= 2
        if cells > size:
            break
    out /= total
    lo, hi = np.percentile(out, [1, 99])
    return np.clip((out - lo) / max(hi - lo, 1e-6), 0, 1)


def _mix(a: np.ndarray, b: np.ndarray, t: np.ndarray) -> np.ndarray:
    t = t[..., None]
    return a * (1 - t) + b * t


def _to_u8(img: np.ndarray) -> np.ndarray:
    return np.clip(img, 0, 255).astype(np.uint8)


def carpet(rng: np.random.Generator, size: int = 512) -> np.ndarray:
    """Speckled loop-pile carpet tile with a faint darker pattern."""
    base = np.array(rng.choice([[70, 80, 105], [95, 85, 75], [80, 95, 85]]), np.float32)
    n1 = noise(rng, size, 6, 8)
    speck = rng.random((size, size)).astype(np.float32)
    speck = cv2.GaussianBlur(speck, (0, 0), 0.8)
    img = base * (0.75 + 0.35 * n1[..., None]) * (0.8 + 0.4 * speck[..., None])
    dots = rng.random((size, size)) > 0.985
    img[dots] = img[dots] * 0.55
    return _to_u8(img)


def wood(rng: np.random.Generator, size: int = 512, light: bool = True) -> np.ndarray:
    """Wood grain running along the image rows."""
    yy, xx = np.mgrid[0:size, 0:size].astype(np.float32) / size
    warp = noise(rng, size, 4, 3)
    rings = np.sin((yy * 18 + warp * 3.0 + 0.2 * np.sin(xx * 6)) * np.pi * 2)
    fine = noise(rng, size, 6, 32)
    t = 0.5 + 0.25 * rings + 0.25 * (fine - 0.5)
    c0 = np.array([175, 130, 85] if light else [110, 70, 40], np.float32)
    c1 = np.array([135, 90, 50] if light else [70, 42, 22], np.float32)
    img = _mix(c0, c1, np.clip(t, 0, 1))
    streak = cv2.resize(rng.random((size, 8)).astype(np.float32), (size, size))
    return _to_u8(img * (0.9 + 0.2 * streak[..., None]))


def plaster(rng: np.random.Generator, size: int = 256, tint=(228, 226, 218)) -> np.ndarray:
    """Painted wall: almost textureless."""
    n = noise(rng, size, 3, 4)
    img = np.array(tint, np.float32) * (0.96 + 0.05 * n[..., None])
    return _to_u8(img)


def ceiling_tiles(rng: np.random.Generator, size: int = 512) -> np.ndarray:
    """Acoustic ceiling tile: pale with pinholes and a grid edge."""
    img = (
        np.full((size, size, 3), 232, np.float32)
        * (0.97 + 0.04 * noise(rng, size, 4, 8))[..., None]
    )
    holes = rng.random((size, size)) > 0.992
    img[holes] *= 0.6
    img[:4, :] = 150
    img[:, :4] = 150
    return _to_u8(img)


def text_block(
    img: np.ndarray, rng: np.random.Generator, x0: int, y0: int, x1: int, y1: int, color
) -> None:
    """Draw lines of random words into the box (x0, y0)-(x1, y1) in place."""
    scale = rng.uniform(0.6, 1.6) * (img.shape[1] / 512)
    thick = max(1, round(scale * 1.5))
    y = y0 + int(25 * scale)
    while y < y1:
        words = " ".join(rng.choice(_WORDS, size=rng.integers(2, 6)))
        cv2.putText(img, words, (x0, y), cv2.FONT_HERSHEY_SIMPLEX, scale, color, thick, cv2.LINE_AA)
        y += int(rng.uniform(28, 40) * scale)


def poster(rng: np.random.Generator, w: int = 512, h: int = 720) -> np.ndarray:
    """A poster: gradient, geometric shapes, a photo-like noise panel and text."""
    c0 = rng.integers(30, 230, 3).astype(np.float32)
    c1 = rng.integers(30, 230, 3).astype(np.float32)
    t = np.linspace(0, 1, h, dtype=np.float32)[:, None] * np.ones((1, w), np.float32)
    img = _mix(c0, c1, t).astype(np.uint8).copy()
    for _ in range(rng.integers(6, 14)):
        color = tuple(int(c) for c in rng.integers(0, 255, 3))
        kind = rng.integers(0, 3)
        if kind == 0:
            center = (int(rng.integers(0, w)), int(rng.integers(0, h)))
            cv2.circle(img, center, int(rng.integers(15, w // 4)), color, -1, cv2.LINE_AA)
        elif kind == 1:
            p = rng.integers(0, [w, h, w, h])
            cv2.rectangle(img, (int(p[0]), int(p[1])), (int(p[2]), int(p[3])), color, -1)
        else:
            pts = rng.integers(0, [w, h], size=(3, 2)).astype(np.int32)
            cv2.fillPoly(img, [pts], color, cv2.LINE_AA)
    # a "photo" panel
    px0, py0 = int(w * 0.1), int(h * 0.35)
    pw, ph = int(w * 0.8), int(h * 0.3)
    panel = np.stack([noise(rng, max(pw, ph), 6, 4)[:ph, :pw] for _ in range(3)], -1) * 255
    img[py0 : py0 + ph, px0 : px0 + pw] = panel.astype(np.uint8)
    fg = (255, 255, 255) if img.mean() < 110 else (20, 20, 20)
    title = " ".join(rng.choice(_WORDS, size=2))
    cv2.putText(
        img, title, (int(w * 0.06), int(h * 0.14)), cv2.FONT_HERSHEY_DUPLEX, w / 300, fg, 3,
        cv2.LINE_AA,
    )  # fmt: skip
    text_block(img, rng, int(w * 0.08), int(h * 0.68), w - 10, h - 20, fg)
    return img


def books(rng: np.random.Generator, w: int = 1024, h: int = 256) -> np.ndarray:
    """A row of book spines with titles, as seen on a shelf."""
    img = np.full((h, w, 3), 40, np.uint8)
    x = 0
    while x < w:
        bw = min(int(rng.integers(14, 42) * w / 1024), w - x)
        if bw < 4:
            break
        bh = int(h * rng.uniform(0.7, 0.98))
        color = tuple(int(c) for c in rng.integers(20, 235, 3))
        cv2.rectangle(img, (x, h - bh), (x + bw - 2, h - 1), color, -1)
        band = tuple(int(255 - c) for c in color)
        y_band = h - bh + int(bh * rng.uniform(0.1, 0.3))
        cv2.rectangle(img, (x, y_band), (x + bw - 2, y_band + max(2, bh // 20)), band, -1)
        spine = np.zeros((bw, bh, 3), np.uint8)
        spine[:] = color
        word = str(rng.choice(_WORDS))
        cv2.putText(
            spine, word, (4, int(bw * 0.7)), cv2.FONT_HERSHEY_PLAIN, bw / 22, band, 1, cv2.LINE_AA
        )
        img[h - bh : h, x : x + bw] = np.rot90(spine)[:, :bw][:bh]
        x += bw
    return img


def cardboard(rng: np.random.Generator, size: int = 512) -> np.ndarray:
    """Brown corrugated cardboard with printed labels and arrows."""
    base = np.array([120, 160, 190][::-1], np.float32)  # RGB (190,160,120)
    img = base * (0.85 + 0.25 * noise(rng, size, 5, 8)[..., None])
    img = img.astype(np.uint8).copy()
    cv2.rectangle(img, (size // 10, size // 10), (size // 2, size // 3), (240, 240, 235), -1)
    text_block(img, rng, size // 10 + 5, size // 10, size // 2 - 5, size // 3, (30, 30, 30))
    for _ in range(2):
        x, y = rng.integers(size // 2, size - 60, 2)
        cv2.arrowedLine(
            img, (int(x), int(y + 50)), (int(x), int(y)), (40, 40, 40), 5, tipLength=0.4
        )
    for k in range(rng.integers(1, 3)):
        word = str(rng.choice(_WORDS))
        cv2.putText(
            img, word, (size // 8, int(size * (0.6 + 0.15 * k))), cv2.FONT_HERSHEY_SIMPLEX,
            size / 300, (35, 35, 60), 4, cv2.LINE_AA,
        )  # fmt: skip
    return img


def cork(rng: np.random.Generator, size: int = 768) -> np.ndarray:
    """A cork notice board with pinned notes."""
    n = noise(rng, size, 6, 16)
    grain = rng.random((size, size)).astype(np.float32)
    img = np.array([170, 120, 75], np.float32) * (
        0.7 + 0.3 * n[..., None] + 0.15 * grain[..., None]
    )
    img = _to_u8(img).copy()
    for _ in range(rng.integers(5, 9)):
        nw, nh = rng.integers(size // 6, size // 3, 2)
        x, y = rng.integers(0, size - nw), rng.integers(0, size - nh)
        paper = tuple(
            int(c) for c in rng.choice([[250, 250, 245], [250, 240, 130], [180, 230, 250]])
        )
        cv2.rectangle(img, (int(x), int(y)), (int(x + nw), int(y + nh)), paper, -1)
        text_block(img, rng, int(x + 6), int(y), int(x + nw - 6), int(y + nh - 5), (20, 20, 120))
        cv2.circle(img, (int(x + nw // 2), int(y + 8)), 6, (200, 20, 20), -1)
    return img


def whiteboard(rng: np.random.Generator, w: int = 1024, h: int = 512) -> np.ndarray:
    """A whiteboard: mostly blank, a few marker strokes."""
    img = np.full((h, w, 3), 246, np.uint8)
    for _ in range(rng.integers(2, 4)):
        pts = np.cumsum(rng.normal(0, 12, size=(20, 2)), axis=0) + rng.integers(
            100, [w - 100, h - 100]
        )
        cv2.polylines(img, [pts.astype(np.int32)], False, (40, 60, 160), 3, cv2.LINE_AA)
    cv2.rectangle(img, (0, 0), (w - 1, h - 1), (170, 170, 175), 10)
    return img


def metal(rng: np.random.Generator, size: int = 256, tint=(165, 170, 175)) -> np.ndarray:
    """Brushed metal: horizontal streaks, low texture."""
    streak = cv2.resize(rng.random((size, 4)).astype(np.float32), (size, size))
    fine = cv2.resize(rng.random((size, 64)).astype(np.float32), (size, size))
    img = np.array(tint, np.float32) * (0.9 + 0.07 * streak[..., None] + 0.05 * fine[..., None])
    return _to_u8(img)


def fabric(rng: np.random.Generator, size: int = 256) -> np.ndarray:
    """Woven upholstery."""
    yy, xx = np.mgrid[0:size, 0:size]
    weave = ((xx // 3 + yy // 3) % 2).astype(np.float32)
    base = rng.integers(40, 160, 3).astype(np.float32)
    img = base * (0.75 + 0.2 * weave[..., None] + 0.2 * noise(rng, size, 5, 8)[..., None])
    return _to_u8(img)


def flat(color) -> np.ndarray:
    """A 1x1 flat-colour texture."""
    return np.array(color, np.uint8).reshape(1, 1, 3)


def framed_picture(rng: np.random.Generator, w: int = 640, h: int = 480) -> np.ndarray:
    """A framed landscape-like picture."""
    sky = noise(rng, max(w, h), 5, 3)[:h, :w]
    img = np.zeros((h, w, 3), np.float32)
    horizon = (0.45 + 0.2 * noise(rng, w, 3, 3)[0])[None, :] * h
    yy = np.arange(h)[:, None]
    is_sky = yy < horizon
    img[:] = np.where(
        is_sky[..., None],
        np.array([120, 170, 225]) * (0.8 + 0.3 * sky[..., None]),
        np.array([70, 120, 50]) * (0.6 + 0.6 * sky[..., None]),
    )
    img = _to_u8(img).copy()
    cv2.rectangle(img, (0, 0), (w - 1, h - 1), (35, 25, 20), 24)
    return img


def door(rng: np.random.Generator, w: int = 512, h: int = 1024) -> np.ndarray:
    """A wooden door with panels, a sign and a handle."""
    img = np.ascontiguousarray(np.rot90(wood(rng, max(w, h), light=False))[:h, :w]).copy()
    for y0, y1 in ((0.08, 0.45), (0.55, 0.92)):
        cv2.rectangle(
            img, (int(w * 0.12), int(h * y0)), (int(w * 0.88), int(h * y1)), (55, 35, 20), 6
        )
    cv2.rectangle(
        img, (int(w * 0.3), int(h * 0.25)), (int(w * 0.7), int(h * 0.32)), (235, 235, 225), -1
    )
    cv2.putText(
        img, f"ROOM {rng.integers(100, 999)}", (int(w * 0.32), int(h * 0.30)),
        cv2.FONT_HERSHEY_SIMPLEX, w / 700, (20, 20, 20), 2, cv2.LINE_AA,
    )  # fmt: skip
    cv2.circle(img, (int(w * 0.85), int(h * 0.52)), int(w * 0.035), (200, 200, 190), -1)
    return img


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
    ground = np.array(tint, np.float32) * (0.88 + 0.2 * noise(rng, size, 5, 8)[..., None])
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


def tiles(
    rng: np.random.Generator,
    size: int = 512,
    n: int = 4,
    tint=(225, 225, 220),
    grout=(150, 148, 140),
) -> np.ndarray:
    """Ceramic tiles: ``n`` x ``n`` glazed squares with grout lines, each a little off-tone.

    The grid repeats exactly with the texture (and from tile to tile nearly so): a
    repeating pattern, like a bathroom's or a kitchen's walls and floors.

    Args:
        rng: generator.
        size: texture size (px); the texture tiles.
        n: tiles per side of the texture.
        tint: (3,) glaze colour, 0..255.
        grout: (3,) grout colour, 0..255.

    Returns:
        (size, size, 3) uint8.
    """
    cell = size // n
    tone = 0.94 + 0.1 * rng.random((n, n)).astype(np.float32)
    shade = np.kron(tone, np.ones((cell, cell), np.float32))
    speck = 0.97 + 0.05 * noise(rng, size, 5, 16)
    img = np.array(tint, np.float32) * (shade * speck)[..., None]
    line = max(2, size // 128)
    for k in range(n):
        img[k * cell : k * cell + line, :] = grout
        img[:, k * cell : k * cell + line] = grout
    return _to_u8(img)


def planks(
    rng: np.random.Generator, size: int = 512, rows: int = 6, light: bool = True, plank=(0.3, 0.5)
) -> np.ndarray:
    """Parquet or panelling: ``rows`` rows of wood planks, joints staggered row by row.

    Each plank is cut from one wood-grain image at a random spot and tinted a little
    lighter or darker, so neighbouring planks differ but the pattern repeats with the texture.

    Args:
        rng: generator.
        size: texture size (px); the texture tiles.
        rows: rows of planks.
        light: light or dark wood.
        plank: range of a plank's length, as a fraction of the texture's width.

    Returns:
        (size, size, 3) uint8; the grain and the planks run along the rows.
    """
    grain = wood(rng, size, light=light).astype(np.float32)
    img = np.empty_like(grain)
    h = size // rows
    for r in range(rows):
        length = int(size * rng.uniform(*plank))
        x = -int(rng.integers(0, length))
        while x < size:
            x0, x1 = max(x, 0), min(x + length, size)
            src = int(rng.integers(0, size - h))
            img[r * h : (r + 1) * h, x0:x1] = grain[src : src + h, x0:x1] * rng.uniform(0.8, 1.15)
            img[r * h : (r + 1) * h, x0 : min(x0 + 2, size)] *= 0.55  # the joint
            x += length
        img[r * h : r * h + 2] *= 0.55
    img[rows * h :] = img[:1]  # leftover rows when size is not a multiple of rows
    return _to_u8(img)


def cabinet_front(
    rng: np.random.Generator, doors: int = 2, w: int = 512, h: int = 512, light: bool = True
) -> np.ndarray:
    """The front of a cupboard: ``doors`` wooden doors side by side, each with a groove
    around a raised panel and a metal knob by the gap between the doors.

    Returns:
        (h, w, 3) uint8, to be stretched once over the front.
    """
    img = np.ascontiguousarray(np.rot90(wood(rng, max(w, h), light=light))[:h, :w]).copy()
    dw = w // doors
    dark = (50, 32, 18) if light else (30, 18, 10)
    for k in range(doors):
        x0, x1 = k * dw, (k + 1) * dw - 1
        cv2.rectangle(img, (x0, 0), (x1, h - 1), dark, 4)  # the gaps between doors
        cv2.rectangle(img, (x0 + dw // 8, h // 10), (x1 - dw // 8, h - h // 10), dark, 3)
        knob_x = x1 - dw // 12 if k % 2 == 0 else x0 + dw // 12
        cv2.circle(img, (knob_x, h // 2), max(4, w // 64), (190, 190, 185), -1, cv2.LINE_AA)
        cv2.circle(img, (knob_x, h // 2), max(4, w // 64), (90, 90, 90), 1, cv2.LINE_AA)
    return img
