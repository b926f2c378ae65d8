"""Plan views of the generated rooms (:mod:`scenebot.scene.rooms`), one panel per seed.

Each panel shows, from above, what the robot meets at its own height (the simulator's
collision map: dark where it collides, light where its centre fits, white where it does
not), the walls, windows (blue), partitions and the open door (black), every piece of
furniture (dashed: on legs, the robot drives under it), and the start pose (red).
``python -m scenebot rooms-gallery --seeds 1-8 --out rooms.png`` draws one.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from scenebot.config import BodyConfig
from scenebot.pictures import pyplot
from scenebot.scene.rooms import DRIVE_UNDER, RoomPlan, room_plan, rooms
from scenebot.sim.obstacles import ObstacleMap


def parse_seeds(text: str) -> list[int]:
    """Seeds from text like ``1-8`` or ``1,3,10-12``."""
    seeds: list[int] = []
    for part in text.split(","):
        a, sep, b = part.strip().partition("-")
        seeds += list(range(int(a), int(b) + 1)) if sep else [int(a)]
    return seeds


def _collision_image(ax, plan: RoomPlan, body: BodyConfig) -> None:
    """The collision map at the robot's height: occupied, free for its centre, too tight."""
    cmap = ObstacleMap.build(rooms(plan.seed), body.clearance_m, body.height_m, res=0.02)
    img = np.where(cmap.occupied, 0.35, np.where(cmap.clearance >= body.radius_m, 0.93, 1.0))
    h, w = img.shape
    x0, y0 = cmap.origin - cmap.res / 2
    extent = (x0, x0 + w * cmap.res, y0, y0 + h * cmap.res)
    ax.imshow(img, origin="lower", extent=extent, cmap="gray", vmin=0, vmax=1)


def _panel(ax, seed: int, body: BodyConfig) -> None:
    """One seed's plan view."""
    plan = room_plan(seed)
    _collision_image(ax, plan, body)
    for w in plan.walls:
        ax.plot([w.o[0], w.o[0] + w.u[0]], [w.o[1], w.o[1] + w.u[1]], "k-", lw=2)
    for k, s, width, _, _ in plan.windows:
        w = plan.walls[k]
        t = np.array(w.u) / w.length_m
        a, c = np.array(w.o) + s * t, np.array(w.o) + (s + width) * t
        ax.plot([a[0], c[0]], [a[1], c[1]], "-", color="tab:blue", lw=4)
    for x0, y0, x1, y1 in plan.solids + ([plan.door_leaf] if plan.door_leaf else []):
        ax.fill([x0, x1, x1, x0], [y0, y0, y1, y1], color="k")
    for it in plan.items:
        x0, y0, x1, y1 = it.rect
        ls = "--" if it.kind in DRIVE_UNDER else "-"
        ax.plot([x0, x1, x1, x0, x0], [y0, y0, y1, y1, y0], ls, color="tab:brown", lw=1)
        ax.text((x0 + x1) / 2, (y0 + y1) / 2, it.kind, fontsize=6, ha="center", va="center")
    st = plan.start
    ax.add_patch(_circle(st.x, st.y, body.radius_m))
    ax.arrow(st.x, st.y, 0.4 * math.cos(st.theta), 0.4 * math.sin(st.theta), color="tab:red",
             width=0.03, length_includes_head=True)  # fmt: skip
    d = plan.describe()
    ax.set_title(
        f"seed {seed}: {d['kind']}, {d['size_m'][0]:.1f} x {d['size_m'][1]:.1f} x "
        f"{d['height_m']:.2f} m\nwalls {'/'.join(d['walls'])}, floors {'/'.join(d['floors'])}, "
        f"{len(d['furniture'])} pieces",
        fontsize=8,
    )
    ax.set_aspect("equal")
    ax.tick_params(labelsize=6)


def _circle(x: float, y: float, r: float):
    """The robot's footprint at the start, a matplotlib patch."""
    from matplotlib.patches import Circle

    return Circle((x, y), r, color="tab:red", fill=False, lw=1.5)


def draw_rooms(seeds: list[int], out: Path, body: BodyConfig | None = None) -> Path:
    """Draw the plan views of ``seeds``' rooms into the PNG ``out``.

    Args:
        seeds: the seeds, one panel each (four panels a row).
        out: the PNG to write.
        body: the robot's body (height band and radius of the collision map); default: the
            configured default robot.

    Returns:
        ``out``.
    """
    body = body or BodyConfig()
    plt = pyplot()
    cols = min(4, len(seeds))
    rows = math.ceil(len(seeds) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.4 * cols, 4.0 * rows), squeeze=False)
    for ax, seed in zip(axes.flat, seeds, strict=False):
        _panel(ax, seed, body)
    for ax in axes.flat[len(seeds) :]:
        ax.axis("off")
    fig.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
