"""The static web viewer: ``index.html`` + assets + ``tour_data.js`` + a top-down overview.

Everything is a plain file (the data is a script setting ``window.TOUR_DATA``, not JSON read
with ``fetch``), so the viewer works from ``file://`` and from any static host.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np

from scenebot.tour.path import TourPath

ASSETS = Path(__file__).parent / "viewer"
ASSET_FILES = ("index.html", "viewer.js", "viewer.css")


class OverviewMap:
    """Top-down picture of the cloud and its metres -> pixel mapping.

    Args:
        points: (N, 3) cloud, metres.
        colors: (N, 3) uint8 RGB.
        extra_xy: (K, 2) positions that must be inside the map (path, cameras), metres.
        size_px: longest side, pixels (``tour.viewer.overview_px``).
        margin_m: border around the content, metres (``tour.viewer.overview_margin_m``).
        max_z: points above this height (metres) are left out (the ceiling).
    """

    def __init__(self, points, colors, extra_xy, size_px, margin_m, max_z=None):
        if max_z is not None:  # leave out the ceiling: a cut-away view from above
            low = np.asarray(points)[:, 2] < max_z
            points, colors = np.asarray(points)[low], np.asarray(colors)[low]
        xy = np.concatenate([np.asarray(points)[:, :2], np.asarray(extra_xy).reshape(-1, 2)])
        lo = np.percentile(xy[: len(points)], 0.5, axis=0) if len(points) else xy.min(0)
        hi = np.percentile(xy[: len(points)], 99.5, axis=0) if len(points) else xy.max(0)
        lo = np.minimum(lo, xy[len(points) :].min(0)) - margin_m
        hi = np.maximum(hi, xy[len(points) :].max(0)) + margin_m
        self.lo, self.hi = lo, hi
        self.m_per_px = float(max(hi - lo) / size_px)
        self.width = int(np.ceil((hi[0] - lo[0]) / self.m_per_px))
        self.height = int(np.ceil((hi[1] - lo[1]) / self.m_per_px))
        self.image = self._draw(np.asarray(points), np.asarray(colors))

    def to_px(self, xy: np.ndarray) -> np.ndarray:
        """(K, 2) metres -> (K, 2) pixel coordinates (u right, v down)."""
        xy = np.asarray(xy, np.float64).reshape(-1, 2)
        return np.stack(
            [(xy[:, 0] - self.lo[0]) / self.m_per_px, (self.hi[1] - xy[:, 1]) / self.m_per_px], -1
        )

    def _draw(self, pts: np.ndarray, col: np.ndarray) -> np.ndarray:
        img = np.full((self.height, self.width, 3), 32, np.uint8)
        if len(pts) == 0:
            return img
        uv = np.floor(self.to_px(pts[:, :2])).astype(int)
        ok = (uv[:, 0] >= 0) & (uv[:, 1] >= 0) & (uv[:, 0] < self.width) & (uv[:, 1] < self.height)
        # draw from low to high so the top-most surface shows (a view from above)
        order = np.argsort(pts[ok, 2])
        u, v, c = uv[ok][order, 0], uv[ok][order, 1], col[ok][order]
        img[v, u] = c
        return img


def write_viewer(
    out_dir: Path,
    frame_files: list[str],
    path: TourPath,
    overview: OverviewMap,
    fps: float,
    n_viewpoints: int,
    video: str | None,
    scene: str = "",
) -> Path:
    """Write index.html, its assets, ``overview.png`` and ``tour_data.js``.

    Args:
        out_dir: the tour folder (frames already there).
        frame_files: frame paths relative to ``out_dir``, in order.
        path: the tour path (one pose per frame).
        overview: the top-down map.
        fps: playback rate, frames/s.
        n_viewpoints: clickable viewpoints, spread evenly over the frames.
        video: the video's file name relative to ``out_dir`` or None.
        scene: scene name shown in the header.

    Returns:
        Path of ``index.html``.
    """
    out_dir = Path(out_dir)
    for name in ASSET_FILES:
        shutil.copyfile(ASSETS / name, out_dir / name)
    cv2.imwrite(str(out_dir / "overview.png"), cv2.cvtColor(overview.image, cv2.COLOR_RGB2BGR))
    px = overview.to_px(path.positions[:, :2])
    n = len(frame_files)
    vp_frames = sorted({int(v) for v in np.rint(np.linspace(0, n - 1, min(n_viewpoints, n)))})
    data = {
        "scene": scene,
        "fps": fps,
        "frames": frame_files,
        "video": video,
        "overview": {
            "src": "overview.png",
            "width": overview.width,
            "height": overview.height,
            "m_per_px": overview.m_per_px,
            "origin_xy_m": [float(overview.lo[0]), float(overview.hi[1])],
        },
        "path_px": [[round(float(u), 2), round(float(v), 2)] for u, v in px],
        "headings": [round(float(h), 4) for h in path.headings],
        "positions_m": [[round(float(c), 4) for c in p] for p in path.positions],
        "viewpoints": [
            {"frame": f, "u": round(float(px[f, 0]), 2), "v": round(float(px[f, 1]), 2)}
            for f in vp_frames
        ],
    }
    (out_dir / "tour_data.js").write_text(
        "// written by scenebot.tour (the tour stage); read by viewer.js\n"
        f"window.TOUR_DATA = {json.dumps(data)};\n"
    )
    return out_dir / "index.html"
