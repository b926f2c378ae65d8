"""The score stage's picture: the highest-scoring candidates' per-pixel scores (matplotlib, Agg)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scenebot.pictures import pyplot


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
    plt = pyplot()
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
