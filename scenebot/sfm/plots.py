"""Pictures of the sfm stage: the top-down map and the paper's accuracy histograms (Fig. 5b)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pycolmap

from scenebot.sfm.evaluate import M_PER_INCH


def plot_map(rec: pycolmap.Reconstruction, path: Path, title: str = "", max_points=60000) -> None:
    """Top-down view (x right, y up, metres) of the sparse points and camera poses.

    Points are drawn in their colours, restricted to the 1-99 % height range (floor and
    ceiling clutter is kept, stray points are not); cameras are arrows along their viewing
    direction, coloured by capture round (from the ``round_XXX`` in the photo name).
    """
    xyz = np.array([p.xyz for p in rec.points3D.values()]).reshape(-1, 3)
    rgb = np.array([p.color for p in rec.points3D.values()]).reshape(-1, 3) / 255.0
    fig, ax = plt.subplots(figsize=(8, 8), dpi=110)
    if len(xyz):
        lo, hi = np.percentile(xyz, [1, 99], axis=0)
        sel = np.all((xyz[:, :2] >= lo[:2]) & (xyz[:, :2] <= hi[:2]), axis=1)
        idx = np.flatnonzero(sel)
        if len(idx) > max_points:
            idx = np.random.default_rng(0).choice(idx, max_points, replace=False)
        ax.scatter(xyz[idx, 0], xyz[idx, 1], s=1.0, c=rgb[idx], linewidths=0)
    rounds, cs, ds = [], [], []
    for iid in rec.reg_image_ids():
        im = rec.image(iid)
        c = im.projection_center()
        d = im.cam_from_world().rotation.matrix()[2]
        cs.append(c)
        ds.append(d)
        r = 0
        for part in im.name.split("/"):
            if part.startswith("round_") and part[6:].isdigit():
                r = int(part[6:])
        rounds.append(r)
    if cs:
        cs, ds, rounds = np.array(cs), np.array(ds), np.array(rounds)
        span = max(float(np.ptp(cs[:, 0])), float(np.ptp(cs[:, 1])), 1e-6)
        cmap = plt.get_cmap("tab10")
        for r in np.unique(rounds):
            m = rounds == r
            ax.quiver(
                cs[m, 0],
                cs[m, 1],
                ds[m, 0],
                ds[m, 1],
                color=cmap(int(r) % 10),
                angles="xy",
                scale_units="xy",
                scale=1.0 / (0.06 * span),
                width=0.004,
                label=f"round {r} ({m.sum()} photos)",
            )
        ax.legend(loc="upper right", fontsize=8)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(
        title
        or f"sparse map: {rec.num_reg_images()} photos, {rec.num_points3D()} points (top view)"
    )
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def plot_accuracy_histograms(acc: dict, path: Path) -> None:
    """Paper-style (Fig. 5b) histograms: position error (total, line of sight, transverse) in
    inches with a centimetre axis on top, and heading error in degrees."""
    per = acc.get("per_photo", [])
    if not per:  # no true poses (real robot, own photos): say so instead of empty axes
        fig, ax = plt.subplots(figsize=(6, 2), dpi=110)
        ax.axis("off")
        ax.text(0.5, 0.5, acc.get("note", "no true poses: no accuracy evaluation"),
                ha="center", va="center", wrap=True)  # fmt: skip
        fig.savefig(path)
        plt.close(fig)
        return
    fig, axes = plt.subplots(1, 4, figsize=(15, 3.6), dpi=110)
    panels = [
        ("position_error_m", "position error"),
        ("line_of_sight_m", "line-of-sight error"),
        ("transverse_m", "transverse error"),
    ]
    for ax, (key, label) in zip(axes[:3], panels, strict=True):
        v = np.array([p[key] for p in per]) / M_PER_INCH
        ax.hist(v, bins=20, color="0.35", edgecolor="black")
        ax.set_xlabel(f"{label} (inches)")
        ax.set_ylabel("photos")
        top = ax.secondary_xaxis("top", functions=(lambda x: x * 2.54, lambda x: x / 2.54))
        top.set_xlabel("cm")
        med = np.median(v) if len(v) else float("nan")
        ax.axvline(med, color="tab:red", lw=1)
        ax.set_title(f"median {med:.3f} in ({med * 2.54:.2f} cm)", fontsize=9)
    h = np.array([p["heading_error_deg"] for p in per])
    axes[3].hist(h, bins=20, color="0.35", edgecolor="black")
    axes[3].set_xlabel("heading error (degrees)")
    axes[3].set_title(f"median {np.median(h) if len(h) else float('nan'):.3f} deg", fontsize=9)
    fig.suptitle(
        f"SfM camera accuracy after similarity alignment ({acc.get('evaluated', 0)} photos)",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
