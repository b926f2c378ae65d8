"""Writing the tour video: H.264 MP4 through imageio-ffmpeg when installed, else OpenCV mp4v.

Browsers play H.264 (yuv420p) MP4s; OpenCV's mp4v fallback plays in desktop players only.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable
from pathlib import Path

import cv2
import numpy as np

LOG = logging.getLogger(__name__)


def h264_available() -> bool:
    """True when the imageio-ffmpeg package (which ships an ffmpeg with libx264) is installed."""
    try:
        import imageio_ffmpeg  # noqa: F401
    except ImportError:
        return False
    return True


def write_video(
    frames: Iterable[np.ndarray], path: str | Path, fps: float, size: tuple[int, int]
) -> str:
    """Encode RGB frames to an MP4.

    Args:
        frames: (H, W, 3) uint8 RGB frames, all of ``size``.
        path: output ``.mp4``.
        fps: frames per second.
        size: (width, height) pixels (even sizes for H.264; odd ones are padded by ffmpeg).

    Returns:
        The codec used: ``h264`` or ``mp4v``.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    w, h = size
    if h264_available():
        import imageio_ffmpeg

        gen = imageio_ffmpeg.write_frames(
            str(path),
            (w, h),
            fps=fps,
            codec="libx264",
            pix_fmt_in="rgb24",
            pix_fmt_out="yuv420p",
            quality=None,
            bitrate=None,
            macro_block_size=2,
            output_params=["-crf", "20", "-preset", "veryfast", "-movflags", "+faststart"],
            ffmpeg_log_level="error",
        )
        gen.send(None)
        for f in frames:
            gen.send(np.ascontiguousarray(f, np.uint8))
        gen.close()
        return "h264"
    LOG.warning("imageio-ffmpeg not installed: writing mp4v (browsers will not play it)")
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, (w, h))
    if not vw.isOpened():
        raise RuntimeError(f"{path}: OpenCV cannot open an mp4v writer")
    for f in frames:
        vw.write(cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
    vw.release()
    return "mp4v"
