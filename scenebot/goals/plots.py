"""The goals stage's pictures: goals on the score heat map, or the frontier; for a person, the
next shots as frusta and the surface's coverage (matplotlib, Agg)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scenebot.artifacts.freespace import FreeSpace, FreeVolume, draw_freespace
from scenebot.geometry import Intrinsics, frustum_lines
from scenebot.pictures import pyplot


def plot_goals(
    path: str | Path,
    fs: FreeSpace,
    poses: np.ndarray,
    score: np.ndarray,
    goals: np.ndarray,
    title: str,
    abandoned: list[dict] | None = None,
    front: dict | None = None,
) -> None:
    """Score heat map over the free space (candidate positions coloured by view score, degrees)
    with the chosen goals as arrows along their headings, and the goals abandoned in earlier
    rounds (their surroundings not chosen again) as red crosses. With ``front`` (the goals
    stage's open frontiers): the open boundary in green, the frontier goals as green arrows
    (numbered first), the places visited for one as green circles."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 6))
    draw_freespace(ax, fs)
    n_front = 0
    if front is not None:
        n_front = len(front["goals"])
        bxy = fs.cell_centres(front["boundary"])
        ax.scatter(bxy[:, 0], bxy[:, 1], s=3, marker="s", color="limegreen",
                   label=f"open boundary ({len(bxy)} cells)")  # fmt: skip
        for r, g in enumerate(front["goals"]):
            x, y, t = g["x"], g["y"], g["theta"]
            tip = (x + 0.35 * np.cos(t), y + 0.35 * np.sin(t))
            arrow = {"arrowstyle": "-|>", "color": "limegreen", "lw": 2.5}
            ax.annotate("", xy=tip, xytext=(x, y), arrowprops=arrow)
            ax.text(x, y, str(r), color="limegreen", fontsize=9, ha="right", va="top")
        if front["visited"]:
            vxy = np.array([[v["x"], v["y"]] for v in front["visited"]])
            ax.scatter(vxy[:, 0], vxy[:, 1], s=80, facecolors="none", edgecolors="limegreen",
                       label=f"frontiers visited ({len(vxy)})")  # fmt: skip
    ok = np.isfinite(score)
    sc = ax.scatter(poses[ok, 0], poses[ok, 1], c=score[ok], s=9, cmap="inferno", alpha=0.85)
    fig.colorbar(sc, ax=ax, label="view score (deg, higher = poorer predicted rendering)")
    L = 0.35
    for r, g in enumerate(goals):
        x, y, t = poses[g]
        ax.annotate(
            "",
            xy=(x + L * np.cos(t), y + L * np.sin(t)),
            xytext=(x, y),
            arrowprops={"arrowstyle": "-|>", "color": "cyan", "lw": 2},
        )
        ax.text(x, y, str(r + n_front), color="cyan", fontsize=9, ha="right", va="top")
    if abandoned:
        xy = np.array([[a["x"], a["y"]] for a in abandoned])
        ax.scatter(xy[:, 0], xy[:, 1], marker="X", s=90, color="red", ec="k", zorder=5,
                   label=f"abandoned in earlier rounds ({len(xy)})")  # fmt: skip
    if abandoned or front is not None:
        ax.legend(loc="upper right", fontsize=8)
    ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_frontier(
    path: str | Path,
    fs: FreeSpace,
    seen: np.ndarray,
    frontier: np.ndarray,
    centres: np.ndarray,
    goals: list[dict],
    title: str,
) -> None:
    """The frontier baseline's decision: seen and unseen free space, the frontier cells, the
    cameras and the chosen goals as arrows along their headings."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 6))
    img = np.zeros((*fs.mask.shape, 4))
    img[fs.mask & ~seen] = (0.85, 0.55, 0.2, 0.6)  # unseen free: orange
    img[seen] = (0.3, 0.6, 0.9, 0.45)  # seen free: blue
    img[frontier] = (0.8, 0.0, 0.6, 1.0)  # frontier: magenta
    ny, nx = fs.mask.shape
    ext = [fs.origin[0], fs.origin[0] + nx * fs.resolution,
           fs.origin[1], fs.origin[1] + ny * fs.resolution]  # fmt: skip
    draw_freespace(ax, fs)
    ax.imshow(img, origin="lower", extent=ext, interpolation="nearest", zorder=3)
    if len(centres):
        ax.plot(centres[:, 0], centres[:, 1], ".", color="k", ms=3, zorder=4)
    L = 0.35
    for r, g in enumerate(goals):
        x, y, t = g["x"], g["y"], g["theta"]
        ax.annotate(
            "",
            xy=(x + L * np.cos(t), y + L * np.sin(t)),
            xytext=(x, y),
            arrowprops={"arrowstyle": "-|>", "color": "lime", "lw": 2},
            zorder=5,
        )
        ax.text(x, y, str(r), color="lime", fontsize=9, ha="right", va="top", zorder=5)
    ax.set_aspect("equal")
    ax.set_title(title + "\nblue: seen free space, orange: unseen, magenta: frontier")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_person_goals(
    path: str | Path,
    vol: FreeVolume,
    taken: np.ndarray,
    intr: Intrinsics,
    goals: np.ndarray,
    gains: np.ndarray,
    surface: np.ndarray,
    seen_by: np.ndarray,
    abandoned: np.ndarray,
    title: str,
) -> None:
    """A person's advice: the next shots as camera frusta over a top and a side view, with the
    photos already taken and each shot's predicted gain, the earlier shots no photo fulfilled
    (not asked for again), and the surface coloured by how many photos saw it (seen by fewer
    than 2: marked red).

    Args:
        path: output PNG.
        vol: the 3-D free space (drawn as its top and side shadows).
        taken: (S, 5) the photos taken, as x, y, z, theta, pitch.
        intr: the camera.
        goals: (K, 5) the next shots, best first.
        gains: (K,) their view scores (degrees: the predicted rendering error a photo there
            removes).
        surface: (P, 3) mesh vertices (m).
        seen_by: (P,) photos seeing each.
        abandoned: (M, 2) x, y of the earlier shots no photo fulfilled.
        title: figure title.
    """
    from matplotlib.collections import LineCollection

    plt = pyplot()
    fig, axes = plt.subplots(2, 2, figsize=(15, 12))
    o, vx = vol.origin, vol.voxel
    nz, ny, nx = vol.free.shape
    ext = {(0, 1): [o[0], o[0] + nx * vx, o[1], o[1] + ny * vx],
           (0, 2): [o[0], o[0] + nx * vx, o[2], o[2] + nz * vx]}  # fmt: skip
    shadow = {(0, 1): vol.free.any(axis=0), (0, 2): vol.free.any(axis=1)}
    pts = np.concatenate([surface, taken[:, :3]]) if len(surface) else taken[:, :3]
    depth = 0.12 * float(np.max(np.ptp(pts, axis=0))) if len(pts) > 1 else 0.3
    colours = plt.get_cmap("autumn")(np.linspace(0, 0.8, max(len(goals), 1)))
    for col, (a, b) in enumerate(((0, 1), (0, 2))):
        ax = axes[0, col]
        ax.imshow(shadow[(a, b)], origin="lower", extent=ext[(a, b)], cmap="Greys_r",
                  vmin=-1.5, vmax=1.2, interpolation="nearest")  # fmt: skip
        ax.plot(surface[:, a], surface[:, b], ".", color="0.35", ms=1, alpha=0.4)
        segs = frustum_lines(taken, intr, 0.5 * depth)[..., [a, b]].reshape(-1, 2, 2)
        ax.add_collection(LineCollection(segs, colors="tab:blue", linewidths=0.6, alpha=0.7))
        ax.plot(taken[:, a], taken[:, b], "o", color="tab:blue", ms=3, label="photos taken")
        if b == 1 and len(abandoned):
            ax.plot(
                abandoned[:, 0],
                abandoned[:, 1],
                "x",
                color="0.3",
                ms=7,
                mew=1.5,
                label=f"earlier shots unfulfilled ({len(abandoned)}): not asked again",
            )
        for r, g in enumerate(goals):
            segs = frustum_lines(g[None], intr, depth)[0][..., [a, b]]
            ax.add_collection(LineCollection(segs, colors=[colours[r]], linewidths=2))
            ax.text(g[a], g[b], f" {r}: {gains[r]:.0f} deg", color="k", fontsize=9,
                    fontweight="bold", va="bottom")  # fmt: skip
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("yz"[b - 1] + " (m)")
        ax.set_title(("top" if b == 1 else "side") + " view: next shots (rank: predicted gain)")
        ax.autoscale()
    axes[0, 0].legend(loc="upper right", fontsize=8)
    few = seen_by < 2
    for col, (a, b) in enumerate(((0, 1), (0, 2))):
        ax = axes[1, col]
        order = np.argsort(-seen_by) if b == 1 else np.argsort(surface[:, 1])
        top = max(int(seen_by.max(initial=2)), 2)
        sc = ax.scatter(surface[order, a], surface[order, b], c=seen_by[order], s=3,
                        cmap="viridis", vmin=0, vmax=top)  # fmt: skip
        ax.scatter(surface[few, a], surface[few, b], s=6, color="red", marker="x",
                   linewidths=0.6, label="seen by < 2 photos")  # fmt: skip
        ax.plot(taken[:, a], taken[:, b], "o", color="tab:blue", ms=3)
        fig.colorbar(sc, ax=ax, fraction=0.046, label="photos seeing the surface")
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("yz"[b - 1] + " (m)")
        frac = float(few.mean()) if len(few) else 0.0
        ax.set_title(f"coverage ({'top' if b == 1 else 'side'}): {100 * frac:.0f}% of the "
                     "surface seen by < 2 photos")  # fmt: skip
    axes[1, 0].legend(loc="upper right", fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_shot_previews(path: str | Path, tiles: list[np.ndarray], shots: list[dict],
                       title: str) -> None:  # fmt: skip
    """One tile per advised shot: its preview (red where no photo sees the view), captioned
    with the shot's number, predicted gain (deg) and the share of the view marked missing."""
    plt = pyplot()
    n = max(len(tiles), 1)
    cols = min(n, 5)
    rows = -(-n // cols)
    h, w = tiles[0].shape[:2] if tiles else (180, 240)
    fig, axes = plt.subplots(rows, cols, figsize=(cols * (w / 80 + 0.3), rows * (h / 80 + 0.6)),
                             squeeze=False)  # fmt: skip
    for ax in axes.ravel():
        ax.axis("off")
    for ax, tile, shot in zip(axes.ravel(), tiles, shots, strict=False):
        ax.imshow(tile)
        gain = "?" if shot["score_deg"] is None else f"{shot['score_deg']:.1f} deg"
        ax.set_title(f"shot {shot['rank']}: gain {gain}\n"
                     f"{100 * shot['missing_fraction']:.0f}% missing", fontsize=8)  # fmt: skip
    if not tiles:
        axes[0, 0].text(0.5, 0.5, "no shot advised", ha="center", va="center")
    import textwrap

    fig.suptitle(textwrap.fill(title, max(30, int(cols * (w / 80 + 0.3) * 14))), fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
