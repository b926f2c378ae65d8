"""SIFT features of a query photo, exactly as the map's (pycolmap's SIFT, uint8 descriptors)."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import cv2
import numpy as np


@lru_cache(maxsize=4)
def _extractor(first_octave: int, max_features: int, num_threads: int):
    import pycolmap

    opts = pycolmap.FeatureExtractionOptions()
    opts.use_gpu = False
    opts.num_threads = num_threads
    opts.sift.first_octave = first_octave
    opts.sift.max_num_features = max_features
    return pycolmap.FeatureExtractor.create(opts)


def load_gray(image: str | Path | np.ndarray) -> np.ndarray:
    """A photo as a C-contiguous (H, W) uint8 grey image.

    Args:
        image: a path to an image file, or an (H, W) / (H, W, 3) uint8 array (RGB order; the
            grey conversion weights only change the SIFT responses slightly).

    Raises:
        FileNotFoundError: the file does not exist or cannot be decoded.
        ValueError: the array is not an 8-bit image.
    """
    if isinstance(image, str | Path):
        path = Path(image)
        gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        if gray is None:
            raise FileNotFoundError(f"{path}: cannot read the photo (missing or not an image)")
        return np.ascontiguousarray(gray)
    arr = np.asarray(image)
    if arr.dtype != np.uint8 or arr.ndim not in (2, 3):
        raise ValueError(f"expected an (H, W[, 3]) uint8 image, got {arr.dtype} {arr.shape}")
    if arr.ndim == 3:
        arr = cv2.cvtColor(arr, cv2.COLOR_RGB2GRAY)
    return np.ascontiguousarray(arr)


def extract_sift(
    gray: np.ndarray, first_octave: int, max_features: int, num_threads: int
) -> tuple[np.ndarray, np.ndarray]:
    """pycolmap SIFT (CPU) keypoints and descriptors of a grey image.

    Args:
        gray: (H, W) uint8 image.
        first_octave: -1 (COLMAP default, upsampled) or 0 (faster)
            (``localize.sift_first_octave``).
        max_features: most features kept (``localize.sift_max_features``).
        num_threads: extraction threads, -1: all cores (``localize.sift_num_threads``).

    Returns:
        keypoints (n, 2) float64 pixel coordinates (x right, y down; COLMAP convention: the
        centre of the top-left pixel is (0.5, 0.5)), descriptors (n, 128) uint8 (L1-root
        normalised, scaled by 512 and clipped, as COLMAP stores them).
    """
    kps, desc = _extractor(first_octave, max_features, num_threads).extract_from_uint8_array(gray)
    xy = np.array([(k.x, k.y) for k in kps], dtype=np.float64).reshape(-1, 2)
    d = np.asarray(desc.data, dtype=np.uint8).reshape(-1, 128)
    return xy, d
