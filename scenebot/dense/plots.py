"""Pictures of the dense stage: renders of the fused cloud, a depth/normal mosaic and the
plane fill's planes seen from above."""

from __future__ import annotations

from pathlib import Path

import cv2
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import open3d as o3d
import pycolmap

from scenebot.dense import workspace as ws
from scenebot.dense.colmap_io import read_array


def splat(
    points: np.ndarray,
    colors: np.ndarray,
    K: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    width: int,
    height: int,
    radius: int = 1,
) -> np.ndarray:
    """Z-buffered point splatting.

    Args:
        points: (N, 3) world points, metres.
        colors: (N, 3) RGB in [0, 1].
        K: (3, 3) intrinsics, pixels.
        R: (3, 3) cam_from_world rotation.
        t: (3,) cam_from_world translation.
        width: image width, pixels.
        height: image height, pixels.
        radius: splat half size, pixels.

    Returns:
        (height, width, 3) float image, white background.
    """
    pc = points @ R.T + t
    keep = pc[:, 2] > 0.05
    pc, col = pc[keep], colors[keep]
    uv = (pc @ K.T)[:, :2] / pc[:, 2:3]
    order = np.argsort(-pc[:, 2])  # far first, near last (last write wins)
    u = np.floor(uv[order, 0]).astype(np.int64)
    v = np.floor(uv[order, 1]).astype(np.int64)
    z, col = pc[order, 2], col[order]
    img = np.ones((height, width, 3))
    zbuf = np.full((height, width), np.inf)
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            uu, vv = u + dx, v + dy
            ok = (uu >= 0) & (uu < width) & (vv >= 0) & (vv < height)
            uu, vv, zz, cc = uu[ok], vv[ok], z[ok], col[ok]
            closer = zz < zbuf[vv, uu] + 0.02
            uu, vv, zz = uu[closer], vv[closer], zz[closer]
            img[vv, uu] = cc[closer]
            # the pass runs far to near, so a pixel's last write is its nearest point
            zbuf[vv, uu] = np.minimum(zbuf[vv, uu], zz)
    return img


def top_view(
    points: np.ndarray, colors: np.ndarray, max_px: int = 800
) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """The cloud seen from above as an image: each cell shows its highest point's colour.

    Args:
        points: (N, 3) world points, metres (z up).
        colors: (N, 3) RGB in [0, 1].
        max_px: cells along the longer side.

    Returns:
        (H, W, 3) image (white where no point; row 0 at the smallest y) and its extent
        (x0, x1, y0, y1) in metres, as ``imshow(..., origin="lower", extent=...)`` takes them.
    """
    lo = points[:, :2].min(axis=0)
    cell = max(float((points[:, :2].max(axis=0) - lo).max()) / max_px, 1e-6)
    ij = np.minimum(np.floor((points[:, :2] - lo) / cell).astype(np.int64), max_px - 1)
    w, h = int(ij[:, 0].max()) + 1, int(ij[:, 1].max()) + 1
    flat = ij[:, 1] * w + ij[:, 0]
    order = np.lexsort((points[:, 2], flat))  # by cell, then height
    last = np.r_[flat[order][1:] != flat[order][:-1], True]  # each cell's highest point
    top = order[last]
    img = np.ones((h * w, 3))
    img[flat[top]] = colors[top]
    extent = (float(lo[0]), float(lo[0] + w * cell), float(lo[1]), float(lo[1] + h * cell))
    return img.reshape(h, w, 3), extent


def plot_fused_views(
    ply: str | Path, rec: pycolmap.Reconstruction, out: str | Path, num_views: int = 3
) -> None:
    """Render the fused cloud from a top view and from a few registered cameras (pulled back
    0.5 m), side by side, into a PNG.

    Args:
        ply: fused point cloud.
        rec: (undistorted) reconstruction, for the viewpoints.
        out: PNG path.
        num_views: perspective renders besides the top view.
    """
    pcd = o3d.io.read_point_cloud(str(ply))
    pts = np.asarray(pcd.points)
    cols = np.asarray(pcd.colors) if pcd.has_colors() else np.full((len(pts), 3), 0.3)
    ids = sorted(rec.reg_image_ids())
    picks = [ids[int(k)] for k in np.linspace(0, len(ids) - 1, num_views).round()]
    fig, axes = plt.subplots(1, num_views + 1, figsize=(4.2 * (num_views + 1), 3.6))
    ax = axes[0]
    if len(pts):
        img, extent = top_view(pts, cols)
        ax.imshow(img, origin="lower", extent=extent, interpolation="nearest")
    centers = np.array([rec.image(i).projection_center() for i in ids])
    ax.plot(centers[:, 0], centers[:, 1], "r.", ms=3, label="cameras")
    ax.set_aspect("equal")
    ax.set_title(f"top view, {len(pts)} points")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(loc="lower right", fontsize=7)
    for ax, i in zip(axes[1:], picks, strict=True):
        img = rec.image(i)
        cam = rec.camera(img.camera_id)
        scale = 320.0 / max(cam.width, cam.height)
        w, h = round(cam.width * scale), round(cam.height * scale)
        K = cam.calibration_matrix().copy()
        K[:2] *= scale
        pose = img.cam_from_world()
        R = pose.rotation.matrix()
        t = np.asarray(pose.translation) + np.array([0.0, 0.0, 0.5])  # step back 0.5 m
        ax.imshow(splat(pts, cols, K, R, t, w, h))
        ax.set_title(f"from {Path(img.name).name} (-0.5 m)")
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(str(out), dpi=110)
    plt.close(fig)


def normal_to_rgb(normal: np.ndarray) -> np.ndarray:
    """(H, W, 3) camera-frame normals -> RGB in [0, 1] (0 normals -> white)."""
    rgb = 0.5 - 0.5 * normal
    rgb[np.all(normal == 0, axis=-1)] = 1.0
    return np.clip(rgb, 0, 1)


def plot_depth_mosaic(
    dense_dir: str | Path, names: list[str], out: str | Path, max_rows: int = 4
) -> None:
    """Mosaic of image | depth | normal for a few views of the workspace.

    Args:
        dense_dir: dense workspace with geometric maps.
        names: view names with maps.
        out: PNG path.
        max_rows: number of views shown (evenly spaced).
    """
    dense_dir = Path(dense_dir)
    if not names:
        raise ValueError("plot_depth_mosaic: no view to show")
    pick = [names[int(k)] for k in np.linspace(0, len(names) - 1, min(max_rows, len(names)))]
    fig, axes = plt.subplots(len(pick), 3, figsize=(12, 3.2 * len(pick)), squeeze=False)
    for row, name in zip(axes, pick, strict=True):
        bgr = cv2.imread(str(dense_dir / "images" / name))
        depth, normal = ws.read_maps(dense_dir, name, "geometric")
        valid = depth > 0
        row[0].imshow(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
        row[0].set_title(Path(name).name)
        dm = np.where(valid, depth, np.nan)
        im = row[1].imshow(dm, cmap="turbo")
        title = f"depth [m], {100 * valid.mean():.0f}% of pixels"
        measured = dense_dir / "stereo" / "depth_maps_measured" / f"{Path(name).name}.geometric.bin"
        if measured.is_file():  # plane completion ran: say how much was measured
            title += f" ({100 * np.mean(read_array(measured) > 0):.0f}% measured)"
        row[1].set_title(title)
        fig.colorbar(im, ax=row[1], fraction=0.035)
        row[2].imshow(normal_to_rgb(normal))
        row[2].set_title("normal (camera frame)")
        for a in row:
            a.axis("off")
    fig.tight_layout()
    fig.savefig(str(out), dpi=90)
    plt.close(fig)


def plot_planes(planes_npz: str | Path | None, out: str | Path) -> None:
    """Top view of the plane fill's planes (:func:`scenebot.dense.planes.store.save_planes`):
    the floor's and the ceiling's extents, each wall's and object face's extent (its cells
    seen from above, so a wall is a line), and the camera centres, in the map frame.
    ``planes_npz`` None: the plane fill is off, and the picture says so."""
    from scenebot.dense.planes.store import load_planes

    fig, ax = plt.subplots(figsize=(8, 7))
    if planes_npz is None:
        ax.text(0.5, 0.5, "plane fill off (dense.plane_fill.enabled: false)", ha="center")
        ax.axis("off")
        fig.savefig(str(out), dpi=90)
        plt.close(fig)
        return
    planes, centres = load_planes(Path(planes_npz))
    colours = plt.get_cmap("tab10")
    k_wall = 0
    for pl, is_ceiling in planes:
        _, X = pl.cell_centres()
        if not len(X):
            continue
        level = abs(pl.normal[2]) > 0.9
        label = f"{pl.area_m2:.1f} m^2, {pl.inliers} points"
        if is_ceiling:
            ax.scatter(X[:, 0], X[:, 1], s=1.5, marker="s", facecolors="none", linewidths=0.4,
                       edgecolors="tab:blue", label=f"ceiling ({label})")  # fmt: skip
        elif level:
            kind = "floor" if pl.boundary else "level face"
            ax.scatter(X[:, 0], X[:, 1], s=4, marker="s", color="0.8" if pl.boundary else "0.5",
                       label=f"{kind} ({label})")  # fmt: skip
        else:
            kind = "wall" if pl.boundary else "object face"
            ax.scatter(X[:, 0], X[:, 1], s=3, color=colours(k_wall % 10),
                       label=f"{kind} ({label})")  # fmt: skip
            k_wall += 1
    if len(centres):
        ax.scatter(centres[:, 0], centres[:, 1], s=3, color="k", label="cameras")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m] (map)")
    ax.set_ylabel("y [m] (map)")
    ax.set_title("plane fill: the planes' extents seen from above")
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), markerscale=3)
    fig.savefig(str(out), dpi=90, bbox_inches="tight")
    plt.close(fig)
