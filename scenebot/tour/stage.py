"""The tour stage: last map + photos + dense cloud -> frames, tour.mp4, a static web viewer.

Entry point :func:`run`. Writes under ``outputs.tour_dir`` (``results/{scene}/final/tour``):

* ``frames/frame_0000.jpg`` ... the ULR renders along the tour path,
* ``tour.mp4`` (H.264 with imageio-ffmpeg, else mp4v),
* ``index.html`` + ``viewer.js`` + ``viewer.css`` + ``tour_data.js`` + ``overview.png``,
* ``tour_summary.json`` (path, timings, settings) and, with ``eval_holdout > 0``,
  ``tour_eval.json`` (leave-one-out PSNR/SSIM of ULR and the nearest-photo baselines).
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
        dense_ply: fused dense cloud (``results/{scene}/final/dense/fused.ply``).
        freespace_npz: optional free space of the last round (``round_{r}/freespace.npz``).
    """

    sparse_dir: Path
    image_dir: Path
    dense_ply: Path
    freespace_npz: Path | None = None


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


def build_renderer(cfg: TourConfig, inputs: TourInputs):
    """Load the map, the photos and the cloud; initialise taichi; build the ULR renderer.

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
    arch = init_taichi(cfg.taichi_arch, cfg.num_threads)
    proxy = load_proxy(inputs.dense_ply, cfg.proxy)
    sources = load_sources(pycolmap.Reconstruction(str(sparse)), inputs.image_dir)
    return UlrRenderer(proxy, sources, cfg), arch


def _freespace_test(npz: Path | None):
    if npz is None or not Path(npz).is_file():
        return None
    from scenebot.artifacts.freespace import FreeSpace

    fs = FreeSpace.load(npz)
    return fs.contains


def plan_valid_path(cfg: TourConfig, renderer, freespace_npz: Path | None = None):
    """The tour path through the photos' positions, minus poses the proxy barely covers.

    Raises:
        TourInputError: no pose is free and covered by the proxy.
    """
    from scenebot.tour.path import ClearanceChecker, TourPath, plan_tour

    centers = renderer.centers
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
    path = plan_tour(centers, cfg.path, checker, float(np.arctan2(first[1], first[0])))
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
    return TourPath(
        path.positions[keep],
        path.headings[keep],
        path.waypoints,
        path.kind,
        path.dropped + int((~keep).sum()),
    )


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
    t_load = time.perf_counter() - t0
    path = plan_valid_path(cfg, renderer, inputs.freespace_npz)
    cam = tour_camera(cfg, renderer.sources[0].camera)
    names, coverage = [], []
    t1 = time.perf_counter()
    quality = [int(cv2.IMWRITE_JPEG_QUALITY), cfg.viewer.jpeg_quality]

    def frames():
        for i in tqdm(range(len(path)), desc="tour frames", unit="frame", disable=not progress):
            res = renderer.render(cam, *path.pose(i))
            name = f"frames/frame_{i:04d}.jpg"
            cv2.imwrite(str(out / name), cv2.cvtColor(res.image, cv2.COLOR_RGB2BGR), quality)
            names.append(name)
            coverage.append(res.coverage)
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
        "path_kind": path.kind,
        "path_dropped_frames": path.dropped,
        "waypoints_m": path.waypoints.round(4).tolist(),
        "path_length_m": float(np.sum(np.linalg.norm(np.diff(path.positions, axis=0), axis=1))),
        "mean_coverage": float(np.mean(coverage)),
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
    LOG.info("tour: %d frames in %.1f s -> %s", len(names), t_render, out)
    return summary
