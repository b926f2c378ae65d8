"""The tour stage: last map + photos + dense cloud -> frames, tour.mp4, a static web viewer.

Entry point :func:`run`. Writes under ``outputs.tour_dir`` (``results/{scene}/final/tour``):

* ``frames/frame_0000.jpg`` ... the ULR renders along the tour path,
* ``tour.mp4`` (H.264 with imageio-ffmpeg, else mp4v),
* ``index.html`` + ``viewer.js`` + ``viewer.css`` + ``tour_data.js`` + ``overview.png``,
* ``tour_path.png``: the path decision (stops, their order, the path, where it looks),
* ``tour_summary.json`` (path, black pixels per frame, timings, settings) and, with
  ``eval_holdout > 0``, ``tour_eval.json`` (leave-one-out PSNR/SSIM of ULR and the
  nearest-photo baselines).
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from scenebot.tour.camera import Camera, TourInputError
from scenebot.tour.config import TourConfig

LOG = logging.getLogger(__name__)


@dataclass
class TourInputs:
    """Inputs of the tour stage.

    Attributes:
        sparse_dir: COLMAP binary model of the last round (``results/{scene}/round_{r}/sfm``).
        image_dir: folder the model's image names are relative to (``results/{scene}``).
        dense_ply: the prepared proxy (``results/{scene}/final/tour/proxy.npz``, the proxy
            rule) or the fused dense cloud (``final/dense/fused.ply``) to build it from.
        freespace_npz: optional free space of the last round (``round_{r}/freespace.npz``);
            never used for a person's photos.
        photos: the photos are a person's (``robot: photos``): six degrees of freedom, no
            free space, no metric scale assumed (see ``tour.photos_depth_m``).
    """

    sparse_dir: Path
    image_dir: Path
    dense_ply: Path
    freespace_npz: Path | None = None
    photos: bool = False


@dataclass
class TourOutputs:
    """Outputs of the tour stage.

    Attributes:
        tour_dir: output folder (``results/{scene}/final/tour``).
    """

    tour_dir: Path

    @property
    def index_html(self) -> Path:
        return Path(self.tour_dir) / "index.html"

    @property
    def video(self) -> Path:
        return Path(self.tour_dir) / "tour.mp4"

    @property
    def summary_json(self) -> Path:
        return Path(self.tour_dir) / "tour_summary.json"


def tour_camera(cfg: TourConfig, photo_cam: Camera) -> Camera:
    """The undistorted camera of the tour frames (the photos' field of view unless set)."""
    hfov = cfg.hfov_deg if cfg.hfov_deg > 0 else photo_cam.hfov_deg
    return Camera.pinhole(cfg.width, cfg.height, hfov)


def sparse_depth(rec) -> float:
    """The photos' median distance to what they see: per registered photo the median depth
    of its observed sparse points, then the median over photos (model units).

    Raises:
        TourInputError: no photo observes a 3-D point.
    """
    per_photo = []
    for img in rec.images.values():
        if not img.has_pose:
            continue
        ids = [p.point3D_id for p in img.points2D if p.has_point3D()]
        if not ids:
            continue
        pose = img.cam_from_world() if callable(img.cam_from_world) else img.cam_from_world
        R = np.asarray(pose.rotation.matrix(), np.float64)
        X = np.array([rec.points3D[i].xyz for i in ids])
        z = X @ R[2] + float(np.asarray(pose.translation)[2])
        z = z[z > 0]
        if len(z):
            per_photo.append(float(np.median(z)))
    if not per_photo:
        raise TourInputError("the sparse model has no 3-D point seen by a photo: re-run SfM")
    return float(np.median(per_photo))


def scaled_lengths(cfg: TourConfig, factor: float) -> TourConfig:
    """A copy of the settings with every length (the ``*_m`` fields) times ``factor``."""

    def scale(d: dict) -> dict:
        return {
            k: scale(v) if isinstance(v, dict) else (v * factor if k.endswith("_m") else v)
            for k, v in d.items()
        }

    return TourConfig.model_validate(scale(cfg.model_dump()))


def photo_units(cfg: TourConfig, rec) -> tuple[TourConfig, float]:
    """The settings of a person's photos: lengths scaled to the scene (no metric scale).

    Returns:
        (settings with the ``*_m`` lengths times ``factor``, factor): model units per metre
        of a setting, so that the photos' median distance to what they see counts as
        ``tour.photos_depth_m``.
    """
    factor = sparse_depth(rec) / cfg.photos_depth_m
    return scaled_lengths(cfg, factor), factor


def build_renderer(cfg: TourConfig, inputs: TourInputs):
    """Load the map, the photos and the cloud; initialise taichi; build the ULR renderer.

    For a person's photos the renderer gets the scene-scaled settings (:func:`photo_units`);
    ``renderer.cfg`` holds the settings it used.

    Returns:
        (renderer, arch name).
    """
    import pycolmap

    from scenebot.taichi_setup import init_taichi
    from scenebot.tour.proxy import load_proxy
    from scenebot.tour.ulr import UlrRenderer, load_sources

    sparse = Path(inputs.sparse_dir)
    if not (sparse / "images.bin").is_file():
        raise TourInputError(f"{sparse}: no COLMAP model (images.bin); run the sfm stage first")
    rec = pycolmap.Reconstruction(str(sparse))
    if inputs.photos:
        cfg, _ = photo_units(cfg, rec)
    arch = init_taichi(cfg.taichi_arch, cfg.num_threads)
    proxy = load_proxy(inputs.dense_ply, cfg.proxy)
    sources = load_sources(rec, inputs.image_dir)
    return UlrRenderer(proxy, sources, cfg), arch


def _freespace_test(npz: Path | None):
    if npz is None or not Path(npz).is_file():
        return None
    from scenebot.artifacts.freespace import FreeSpace

    fs = FreeSpace.load(npz)
    return fs.contains


def plan_valid_path(
    cfg: TourConfig, renderer, freespace_npz: Path | None = None, photos: bool = False
):
    """The tour path through the photos' positions, looking at what they show, minus poses
    the proxy barely covers.

    Args:
        cfg: tour settings (for a person's photos, the scaled ones: ``renderer.cfg``).
        renderer: the ULR renderer (photos, their targets, the cloud).
        freespace_npz: the robot's free space (ignored for a person's photos).
        photos: a person's photos (3-D path, 3-D clearance, no free space).

    Raises:
        TourInputError: no pose is free and covered by the proxy.
    """
    from scenebot.tour.path import ClearanceChecker, plan_tour

    centers = renderer.centers
    if photos:
        checker = ClearanceChecker(
            renderer.proxy.points, cfg.path.clearance_m, None, 0.0,
            min_points=cfg.path.obstacle_min_points,
        )  # fmt: skip
    else:
        fs = _freespace_test(freespace_npz) if cfg.path.use_freespace else None
        checker = ClearanceChecker(
            renderer.proxy.points,
            cfg.path.clearance_m,
            float(np.median(centers[:, 2])),
            cfg.path.height_band_m,
            fs,
            min_points=cfg.path.obstacle_min_points,
        )
    first = renderer.sources[0].R[2]
    path = plan_tour(
        centers,
        cfg.path,
        checker,
        float(np.arctan2(first[1], first[0])),
        targets=renderer.source_targets(),
        photos=photos,
    )
    # coverage of the view by the cloud at a coarse resolution (splats up to 3 px there, the
    # equivalent of 12 px at 640 px), so gaps between points do not count as missing surface
    small = Camera.pinhole(160, 120, tour_camera(cfg, renderer.sources[0].camera).hfov_deg)
    cov = np.array(
        [
            np.isfinite(renderer.splatter.raw_depth(small, *path.pose(i), max_px=3.0)).mean()
            for i in range(len(path))
        ]
    )
    keep = cov >= cfg.path.min_coverage
    if not keep.any():
        raise TourInputError(
            f"no tour pose sees enough of the dense cloud (best coverage {cov.max():.2f} < "
            f"tour.path.min_coverage={cfg.path.min_coverage}): lower it or check the dense cloud"
        )
    return path.subset(keep)


def draw_path(png: Path, path, renderer, title: str, cut: float) -> None:
    """The path decision from above: the cloud below ``cut`` above the cameras (the ceiling
    cut away), the photos and their targets, the stops in tour order, the path and where it
    looks."""
    from scenebot.pictures import pyplot

    plt = pyplot()
    C = renderer.centers
    low = renderer.proxy.points[:, 2] < np.median(C[:, 2]) + cut
    step = max(1, int(low.sum()) // 60000)
    pts = renderer.proxy.points[low][::step]
    col = renderer.proxy.colors[low][::step] / 255.0
    tg = renderer.source_targets()
    ok = np.all(np.isfinite(tg), axis=1)
    fig, ax = plt.subplots(figsize=(7, 7))
    ax.scatter(pts[:, 0], pts[:, 1], s=0.3, c=col, alpha=0.5, lw=0)
    fw = np.array([s.R[2] for s in renderer.sources])
    ax.quiver(C[:, 0], C[:, 1], fw[:, 0], fw[:, 1], color="tab:blue", width=0.003,
              scale=12, label="photos")  # fmt: skip
    ax.plot(tg[ok, 0], tg[ok, 1], "+", color="tab:blue", ms=5, label="what they look at")
    wp = path.waypoints
    loop = np.concatenate([wp, wp[:1]]) if path.closed else wp
    ax.plot(loop[:, 0], loop[:, 1], ":", color="0.3", lw=0.8, label="stops in tour order")
    for i, w in enumerate(wp):
        ax.annotate(str(i), w[:2], fontsize=7, color="0.2")
    ax.plot(path.positions[:, 0], path.positions[:, 1], "-", color="tab:red", lw=1.5,
            label=f"tour ({path.kind}, {'closed' if path.closed else 'open'})")  # fmt: skip
    every = max(1, len(path) // 40)
    f = path.forward()[::every]
    p = path.positions[::every]
    ax.quiver(p[:, 0], p[:, 1], f[:, 0], f[:, 1], color="tab:red", width=0.004, scale=15,
              label="tour view")  # fmt: skip
    xy = np.concatenate([C[:, :2], path.positions[:, :2], tg[ok, :2]])
    lo, hi = xy.min(0), xy.max(0)
    pad = 0.1 * float((hi - lo).max() or 1.0)
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal")
    ax.legend(loc="upper right", fontsize=7)
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)


def run(cfg: TourConfig, inputs: TourInputs, outputs: TourOutputs, progress: bool = True) -> dict:
    """Render the tour, write the video and the viewer.

    Args:
        cfg: tour settings.
        inputs: map, photos, dense cloud, free space.
        outputs: the tour folder.
        progress: show tqdm progress bars.

    Returns:
        The summary written to ``tour_summary.json``.

    Raises:
        TourInputError: missing or unusable inputs (empty/tiny cloud, no valid tour pose).
    """
    from tqdm import tqdm

    from scenebot.tour.evaluate import leave_one_out
    from scenebot.tour.video import write_video
    from scenebot.tour.viewer import OverviewMap, write_viewer

    t0 = time.perf_counter()
    out = Path(outputs.tour_dir)
    frames_dir = out / "frames"
    frames_dir.mkdir(parents=True, exist_ok=True)
    for old in frames_dir.glob("frame_*.jpg"):
        old.unlink()
    renderer, arch = build_renderer(cfg, inputs)
    cfg = renderer.cfg  # a person's photos: lengths scaled to the scene
    t_load = time.perf_counter() - t0
    path = plan_valid_path(cfg, renderer, inputs.freespace_npz, inputs.photos)
    unit = "model units" if inputs.photos else "m"
    draw_path(
        out / "tour_path.png",
        path,
        renderer,
        f"tour path: {len(path.waypoints)} stops, {len(path)} frames "
        f"({path.dropped} dropped); lengths in {unit}",
        cfg.viewer.overview_cut_m,
    )
    cam = tour_camera(cfg, renderer.sources[0].camera)
    names, coverage, black, fills = [], [], [], []
    t1 = time.perf_counter()
    quality = [int(cv2.IMWRITE_JPEG_QUALITY), cfg.viewer.jpeg_quality]

    def frames():
        for i in tqdm(range(len(path)), desc="tour frames", unit="frame", disable=not progress):
            res = renderer.render(cam, *path.pose(i))
            name = f"frames/frame_{i:04d}.jpg"
            cv2.imwrite(str(out / name), cv2.cvtColor(res.image, cv2.COLOR_RGB2BGR), quality)
            names.append(name)
            coverage.append(res.coverage)
            black.append(res.black_fraction)
            fills.append(res.fill_fractions())
            yield res.image

    codec = None
    if cfg.video:
        codec = write_video(frames(), outputs.video, cfg.viewer.fps, (cam.width, cam.height))
    else:
        for _ in frames():
            pass
    t_render = time.perf_counter() - t1
    extra = np.concatenate([path.positions[:, :2], renderer.centers[:, :2]])
    overview = OverviewMap(
        renderer.proxy.points,
        renderer.proxy.colors,
        extra,
        cfg.viewer.overview_px,
        margin_m=cfg.viewer.overview_margin_m,
        max_z=float(np.median(renderer.centers[:, 2])) + cfg.viewer.overview_cut_m,
    )
    write_viewer(
        out,
        names,
        path,
        overview,
        cfg.viewer.fps,
        cfg.viewer.viewpoints,
        "tour.mp4" if codec else None,
        scene=Path(inputs.image_dir).name,
    )
    summary = {
        "frames": len(names),
        "size": [cam.width, cam.height],
        "hfov_deg": cam.hfov_deg,
        "photos": inputs.photos,
        "length_unit": unit,
        "path_kind": path.kind,
        "path_closed": path.closed,
        "path_dropped_frames": path.dropped,
        "path_max_turn_deg": float(
            np.degrees(np.abs(np.diff(np.stack([path.headings, path.pitches]), axis=1)).max())
        )
        if len(path) > 1
        else 0.0,
        "waypoints_m": path.waypoints.round(4).tolist(),
        "path_length_m": float(np.sum(np.linalg.norm(np.diff(path.positions, axis=0), axis=1))),
        "mean_coverage": float(np.mean(coverage)),
        "black_fraction_per_frame": [round(b, 5) for b in black],
        "mean_black_fraction": float(np.mean(black)),
        "max_black_fraction": float(np.max(black)),
        "mean_fill_fractions": {k: float(np.mean([f[k] for f in fills])) for k in fills[0]},
        "sources": renderer.num_sources,
        "proxy_points": len(renderer.proxy),
        "taichi_arch": arch,
        "video_codec": codec,
        "load_s": t_load,
        "render_s": t_render,
        "render_s_per_frame": t_render / max(len(names), 1),
        "config": cfg.model_dump(),
    }
    if cfg.eval_holdout > 0 and renderer.num_sources >= 2:
        ev = leave_one_out(renderer, cfg.eval_holdout, progress=progress)
        (out / "tour_eval.json").write_text(json.dumps(ev, indent=1))
        summary["eval"] = ev["summary"]
    summary["total_s"] = time.perf_counter() - t0
    outputs.summary_json.write_text(json.dumps(summary, indent=1))
    LOG.info(
        "tour: %d frames in %.1f s, black pixels %.2f%% mean, %.2f%% worst frame -> %s",
        len(names), t_render, 100 * summary["mean_black_fraction"],
        100 * summary["max_black_fraction"], out,
    )  # fmt: skip
    return summary
