"""Read and write COLMAP dense arrays (depth maps, normal maps).

COLMAP stores a ``Mat<float>`` as an ASCII header ``"{width}&{height}&{channels}&"`` followed
by little-endian float32 values ordered channel-major, then row-major inside a channel:
``value(row, col, ch) = data[ch * width * height + row * width + col]`` (this is what
``colmap/scripts/python/read_write_dense.py`` reads as a Fortran-ordered (W, H, C) array).
Depth maps hold z-depth in model units (0 = no depth); normal maps hold unit normals in the
camera frame (x right, y down, z forward), pointing towards the camera.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def read_array(path: str | Path) -> np.ndarray:
    """Read a COLMAP dense array.

    Args:
        path: ``*.bin`` file written by COLMAP or :func:`write_array`.

    Returns:
        float32 array of shape (H, W) for one channel or (H, W, C) for several.

    Raises:
        FileNotFoundError: the file does not exist.
        ValueError: the header or the payload size is malformed.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"COLMAP dense array {path} does not exist")
    raw = path.read_bytes()
    fields: list[int] = []
    pos = 0
    for _ in range(3):
        amp = raw.find(b"&", pos)
        if amp < 0 or amp - pos > 12:
            raise ValueError(f"{path}: malformed header, expected 'width&height&channels&'")
        try:
            fields.append(int(raw[pos:amp].decode("ascii")))
        except ValueError as exc:
            raise ValueError(f"{path}: malformed header field {raw[pos:amp]!r}") from exc
        pos = amp + 1
    width, height, channels = fields
    data = np.frombuffer(raw, dtype="<f4", offset=pos)
    if data.size != width * height * channels:
        raise ValueError(
            f"{path}: header says {width}x{height}x{channels} but holds {data.size} floats"
        )
    arr = data.reshape(channels, height, width).transpose(1, 2, 0).astype(np.float32)
    return arr[:, :, 0] if channels == 1 else arr


def write_array(path: str | Path, array: np.ndarray) -> None:
    """Write a COLMAP dense array.

    Args:
        path: destination ``*.bin`` file (parent folders are created).
        array: (H, W) or (H, W, C) array; stored as float32.
    """
    arr = np.asarray(array, dtype=np.float32)
    if arr.ndim == 2:
        arr = arr[:, :, None]
    if arr.ndim != 3:
        raise ValueError(f"write_array expects (H, W) or (H, W, C), got shape {arr.shape}")
    height, width, channels = arr.shape
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as fh:
        fh.write(f"{width}&{height}&{channels}&".encode("ascii"))
        fh.write(np.ascontiguousarray(arr.transpose(2, 0, 1)).astype("<f4").tobytes())
