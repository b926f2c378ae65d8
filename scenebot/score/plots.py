"""Pictures of what the mesh, score and goals stages decided (matplotlib, Agg backend)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scenebot.score.freespace import FreeSpace


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _draw_freespace(ax, fs: FreeSpace) -> None:
    ny, nx = fs.mask.shape
    ext = [fs.origin[0], fs.origin[0] + nx * fs.resolution]
    ext += [fs.origin[1], fs.origin[1] + ny * fs.resolution]
    ax.imshow(fs.mask, origin="lower", extent=ext, cmap="Greys_r", vmin=-1.5, vmax=1.2)
    if len(fs.segments):
        from matplotlib.collections import LineCollection

        ax.add_collection(LineCollection(fs.segments, colors="k", linewidths=0.8))
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")


def plot_freespace(path: str | Path, fs: FreeSpace, cam_xy: np.ndarray, title: str) -> None:
    """Free space (light), mesh cut (black lines) and camera centres (blue dots)."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 6))
    _draw_freespace(ax, fs)
    ax.plot(cam_xy[:, 0], cam_xy[:, 1], ".", color="tab:blue", ms=3, label="cameras")
    ax.set_title(f"{title}: free space {fs.area_m2:.2f} m^2, closed={fs.closed}")
    ax.legend(loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


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
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 6))
    _draw_freespace(ax, fs)
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
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 6))
    img = np.zeros((*fs.mask.shape, 4))
    img[fs.mask & ~seen] = (0.85, 0.55, 0.2, 0.6)  # unseen free: orange
    img[seen] = (0.3, 0.6, 0.9, 0.45)  # seen free: blue
    img[frontier] = (0.8, 0.0, 0.6, 1.0)  # frontier: magenta
    ny, nx = fs.mask.shape
    ext = [fs.origin[0], fs.origin[0] + nx * fs.resolution,
           fs.origin[1], fs.origin[1] + ny * fs.resolution]  # fmt: skip
    _draw_freespace(ax, fs)
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


def plot_top_views(
    path: str | Path, depth: np.ndarray, pixels: np.ndarray, scores: np.ndarray, title: str
) -> None:
    """Per-pixel score images (degrees) of the top candidates next to their mesh renders.

    Args:
        path: output PNG.
        depth: (K, H, W) z-depth renders (m; >= 1e29 where nothing is hit).
        pixels: (K, H, W) pixel scores (degrees; < 0 where nothing is hit).
        scores: (K,) view scores (degrees).
        title: figure title.
    """
    plt = _plt()
    k = len(depth)
    fig, axes = plt.subplots(k, 2, figsize=(7, 2.6 * max(k, 1)), squeeze=False)
    for r in range(k):
        d = np.where(depth[r] < 1e29, depth[r], np.nan)
        axes[r, 0].imshow(d, cmap="viridis_r")
        axes[r, 0].set_title(f"#{r} mesh depth (m)", fontsize=9)
        p = np.where(pixels[r] >= 0, pixels[r], np.nan)
        im = axes[r, 1].imshow(p, cmap="inferno", vmin=0, vmax=180)
        axes[r, 1].set_title(f"#{r} pixel score, view {scores[r]:.1f} deg", fontsize=9)
        fig.colorbar(im, ax=axes[r, 1], fraction=0.046)
        for a in axes[r]:
            a.set_xticks([])
            a.set_yticks([])
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
