"""The mesh stage's picture: the free space and the map's cameras (matplotlib, Agg)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scenebot.artifacts.freespace import FreeSpace, FreeVolume, draw_freespace
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


def plot_volume(path: str | Path, vol: FreeVolume, pts: np.ndarray, title: str) -> None:
    """The 3-D free space of a person's photos: the top view at the photos' median camera
    height, the side view (x-z) through the map points' median y, and the top view of how many
    free voxels each column holds; cameras (blue) and map points (grey) drawn on each."""
    plt = pyplot()
    o, v = vol.origin, vol.voxel
    nz, ny, nx = vol.free.shape
    x1, y1, z1 = o[0] + nx * v, o[1] + ny * v, o[2] + nz * v
    zc = vol.camera_height
    yc = float(np.median(pts[:, 1])) if len(pts) else float(np.median(vol.cameras[:, 1]))
    j = int(np.clip(np.floor((yc - o[1]) / v), 0, ny - 1))
    cams = vol.cameras
    fig, axes = plt.subplots(1, 3, figsize=(16, 5.5))
    panels = [
        (vol.layer(zc), [o[0], x1, o[1], y1], (0, 1), f"top: free at camera height z = {zc:.2f}"),
        (vol.free[:, j, :], [o[0], x1, o[2], z1], (0, 2), f"side: free at y = {yc:.2f}"),
        (vol.free.sum(axis=0) * v, [o[0], x1, o[1], y1], (0, 1), "top: free height per column"),
    ]
    for ax, (img, ext, (a, b), name) in zip(axes, panels, strict=True):
        binary = img.dtype == bool
        im = ax.imshow(img, origin="lower", extent=ext, interpolation="nearest",
                       cmap="Greys_r" if binary else "viridis",
                       vmin=-1.5 if binary else 0, vmax=1.2 if binary else None)  # fmt: skip
        if not binary:
            fig.colorbar(im, ax=ax, fraction=0.046, label="free height (m)")
        if len(pts):
            ax.plot(pts[:, a], pts[:, b], ".", color="0.45", ms=1, alpha=0.5)
        ax.plot(cams[:, a], cams[:, b], "o", color="tab:blue", ms=3, label="cameras")
        ax.set_xlim(ext[0], ext[1])
        ax.set_ylim(ext[2], ext[3])
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("yz"[b - 1] + " (m)")
        ax.set_title(name, fontsize=10)
    axes[0].legend(loc="upper right", fontsize=8)
    fig.suptitle(
        f"{title}: 3-D free space {vol.volume_m3:.3g} m^3 ({vol.n_free} voxels of "
        f"{vol.voxel:.3g} m), seen through by the photos' lines of sight"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
