"""The mesh stage's picture: the free space and the map's cameras (matplotlib, Agg)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scenebot.artifacts.freespace import FreeSpace, draw_freespace
from scenebot.pictures import pyplot


def plot_freespace(path: str | Path, fs: FreeSpace, cam_xy: np.ndarray, title: str) -> None:
    """Free space (light), mesh cut (black lines) and camera centres (blue dots)."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 6))
    draw_freespace(ax, fs)
    ax.plot(cam_xy[:, 0], cam_xy[:, 1], ".", color="tab:blue", ms=3, label="cameras")
    ax.set_title(f"{title}: free space {fs.area_m2:.2f} m^2, closed={fs.closed}")
    ax.legend(loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
