"""A picture of the navigation grid, the paths and the goals (like the paper's Fig. 4)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from scenebot.plan.navgrid import NavGrid


def plot_navgrid(
    grid: NavGrid,
    paths: Sequence[np.ndarray],
    out_png: Path,
    goals_xy: np.ndarray | None = None,
    skipped_xy: np.ndarray | None = None,
    camera_xy: np.ndarray | None = None,
    title: str = "navigation grid",
) -> Path:
    """Draw costs (darker = costlier), lethal cells, paths with lettered nodes, goals.

    Args:
        grid: the navigation grid.
        paths: list of (M, 2) waypoint arrays (m, map frame).
        out_png: output file.
        goals_xy: (G, 2) planned goals (m).
        skipped_xy: (S, 2) goals that were skipped (m), drawn as red crosses.
        camera_xy: (C, 2) camera centres of the map (m), drawn as small dots.
        title: figure title.

    Returns:
        ``out_png``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    g = grid.geometry
    ny, nx = g.shape
    extent = (
        g.origin_xy[0],
        g.origin_xy[0] + nx * g.cell_m,
        g.origin_xy[1],
        g.origin_xy[1] + ny * g.cell_m,
    )
    fig, ax = plt.subplots(figsize=(7, 7 * ny / max(nx, 1) + 0.6))
    shade = np.log1p(grid.score)
    ax.imshow(shade, origin="lower", extent=extent, cmap="Greys", interpolation="nearest")
    red = np.zeros((ny, nx, 4))
    red[grid.lethal] = (0.8, 0.1, 0.1, 0.25)
    ax.imshow(red, origin="lower", extent=extent, interpolation="nearest")
    if camera_xy is not None and len(camera_xy):
        c = np.asarray(camera_xy)
        ax.plot(c[:, 0], c[:, 1], ".", ms=2, color="tab:green", label="map cameras")
    letters = "ABCDEFGHIJKLMNOPQRSTUVWXYZ"
    for k, wp in enumerate(paths):
        wp = np.asarray(wp)
        ax.plot(wp[:, 0], wp[:, 1], "-o", color=f"C{k % 10}", ms=4, lw=1.5)
        if k == 0:
            for i, (x, y) in enumerate(wp):
                ax.annotate(letters[i % 26], (x, y), textcoords="offset points", xytext=(4, 4))
    if goals_xy is not None and len(goals_xy):
        gx = np.asarray(goals_xy)
        ax.plot(gx[:, 0], gx[:, 1], "*", ms=12, color="gold", mec="k", label="goals")
    if skipped_xy is not None and len(skipped_xy):
        sx = np.asarray(skipped_xy)
        ax.plot(sx[:, 0], sx[:, 1], "x", ms=10, mew=2, color="red", label="skipped goals")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title)
    ax.set_aspect("equal")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper right", fontsize=8)
    out_png = Path(out_png)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out_png, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return out_png
