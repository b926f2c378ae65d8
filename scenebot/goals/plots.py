"""The goals stage's pictures: goals on the score heat map, or the frontier (matplotlib, Agg)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scenebot.artifacts.freespace import FreeSpace, draw_freespace
from scenebot.pictures import pyplot


def plot_goals(
    path: str | Path,
    fs: FreeSpace,
    poses: np.ndarray,
    score: np.ndarray,
    goals: np.ndarray,
    title: str,
) -> None:
    """Score heat map over the free space (candidate positions coloured by view score, degrees)
    with the chosen goals as arrows along their headings."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 6))
    draw_freespace(ax, fs)
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
        ax.text(x, y, str(r), color="cyan", fontsize=9, ha="right", va="top")
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
