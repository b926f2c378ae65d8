"""Writing and checking JPEG photos with the EXIF tags photogrammetry tools read.

COLMAP and most SfM tools derive the focal length in pixels from EXIF: the 35 mm equivalent
focal length, or the focal length in mm with the focal-plane resolution (pixels per unit) or
a sensor database. We write all of them so any reader finds a consistent value.
"""

from __future__ import annotations

import datetime as _dt
import errno
import math
import os
import shutil
from collections.abc import Callable
from fractions import Fraction
from pathlib import Path

import numpy as np
from PIL import Image, TiffImagePlugin

EXIF_IFD = 0x8769
TAG_MAKE = 0x010F
TAG_MODEL = 0x0110
TAG_DATETIME_ORIGINAL = 0x9003
TAG_FOCAL_LENGTH = 0x920A
TAG_FOCAL_35MM = 0xA405
TAG_FOCAL_PLANE_XRES = 0xA20E
TAG_FOCAL_PLANE_YRES = 0xA20F
TAG_FOCAL_PLANE_UNIT = 0xA210
UNIT_CM = 3
FULL_FRAME_DIAGONAL_MM = math.hypot(36.0, 24.0)
"""35 mm equivalents scale by the image diagonal (as COLMAP reads them)."""


def _rational(x: float) -> TiffImagePlugin.IFDRational:
    f = Fraction(x).limit_denominator(100000)
    return TiffImagePlugin.IFDRational(f.numerator, f.denominator)


def write_jpeg(
    path: Path,
    rgb: np.ndarray,
    focal_px: float,
    sensor_width_mm: float,
    quality: int = 92,
    make: str = "scenebot",
    model: str = "SimCam 640",
    when: _dt.datetime | None = None,
) -> Path:
    """Write an RGB image as a JPEG with EXIF focal length tags, atomically.

    Args:
        path: destination ``.jpg``.
        rgb: (H, W, 3) uint8 image.
        focal_px: focal length in pixels (square pixels).
        sensor_width_mm: physical sensor width used to express the focal length in mm.
        quality: JPEG quality (1-100).
        make, model: EXIF camera make and model.
        when: capture time for DateTimeOriginal.

    Returns:
        The path written.
    """
    path = Path(path)
    h, w = rgb.shape[:2]
    focal_mm = focal_px * sensor_width_mm / w
    exif = Image.Exif()
    exif[TAG_MAKE] = make
    exif[TAG_MODEL] = model
    ifd = exif.get_ifd(EXIF_IFD)
    ifd[TAG_FOCAL_LENGTH] = _rational(focal_mm)
    ifd[TAG_FOCAL_35MM] = round(focal_px * FULL_FRAME_DIAGONAL_MM / math.hypot(w, h))
    px_per_cm = w / (sensor_width_mm / 10.0)
    ifd[TAG_FOCAL_PLANE_XRES] = _rational(px_per_cm)
    ifd[TAG_FOCAL_PLANE_YRES] = _rational(px_per_cm)
    ifd[TAG_FOCAL_PLANE_UNIT] = UNIT_CM
    ifd[TAG_DATETIME_ORIGINAL] = (when or _dt.datetime.now()).strftime("%Y:%m:%d %H:%M:%S")
    tmp = path.with_name(path.name + ".part")
    try:
        Image.fromarray(np.ascontiguousarray(rgb)).save(tmp, "JPEG", quality=quality, exif=exif)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)  # a failed save leaves no partial file behind
    return path


class PhotoWriteError(RuntimeError):
    """A photo could not be stored complete (disk full, I/O error, or a photo of that name
    exists): the capture stops. The message names the photo and the space left."""


def space_left(path: Path) -> str:
    """``"41.0 kB free of 400.0 kB on the file system of <folder>"`` for the nearest existing
    folder of ``path`` (for messages about failed writes)."""
    folder = Path(path)
    while not folder.is_dir() and folder != folder.parent:
        folder = folder.parent
    try:
        du = shutil.disk_usage(folder)
    except OSError as exc:
        return f"free space of {folder} unknown ({exc.strerror})"
    return f"{_size(du.free)} free of {_size(du.total)} on the file system of {folder}"


def _size(n: float) -> str:
    for unit in ("bytes", "kB", "MB", "GB"):
        if n < 1000 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1000.0
    raise AssertionError


def jpeg_problem(path: Path) -> str | None:
    """Why the file at ``path`` is not a complete JPEG (None: it is one): the SOI marker
    first, the EOI marker last, and the whole image decodes."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(2)
            fh.seek(0, os.SEEK_END)
            size = fh.tell()
            fh.seek(max(0, size - 2))
            tail = fh.read(2)
        if head != b"\xff\xd8":
            return f"is not a JPEG ({size} bytes, no start-of-image marker)"
        if tail != b"\xff\xd9":
            return f"is a truncated JPEG ({size} bytes, no end-of-image marker)"
        with Image.open(path) as im:
            im.load()
    except OSError as exc:  # PIL's decode errors are OSErrors too
        return f"does not decode ({exc})"
    return None


def _fsync_dir(folder: Path) -> None:
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    except OSError:  # some file systems cannot sync a directory; the data is synced
        pass
    finally:
        os.close(fd)


def publish(tmp: Path, dest: Path) -> None:
    """Give the complete file ``tmp`` the name ``dest``, atomically, never replacing a file.

    A hard link fails if ``dest`` exists (the atomic test-and-set); then ``tmp`` goes.
    File systems without hard links (FAT on an SD card) get a check and a rename.

    Raises:
        FileExistsError: ``dest`` exists (nothing changed).
    """
    try:
        os.link(tmp, dest)
    except FileExistsError:
        raise
    except OSError as exc:
        if exc.errno not in (errno.EPERM, errno.EOPNOTSUPP, errno.ENOTSUP, errno.EMLINK):
            raise
        if os.path.lexists(dest):
            raise FileExistsError(errno.EEXIST, os.strerror(errno.EEXIST), str(dest)) from None
        os.rename(tmp, dest)
    else:
        os.unlink(tmp)
    _fsync_dir(dest.parent)


def store_photo(dest: Path, write: Callable[[Path], object]) -> Path:
    """Store a photo at ``dest`` complete or not at all, never overwriting one.

    ``write(tmp)`` writes the photo to a temporary name in the same folder; the file is then
    fsynced, verified to be a complete, decodable JPEG (a disk that fills up can leave a
    short file without any error), and renamed to ``dest`` without replacing a file.

    Raises:
        PhotoWriteError: ``dest`` exists, the write failed (the message says how much space
            is left there) or the written file is not a complete JPEG. No file is left.
    """
    dest = Path(dest)
    if os.path.lexists(dest):
        raise PhotoWriteError(f"photo {dest} already exists: refusing to overwrite it")
    tmp = dest.with_name(f".{dest.name}.{os.getpid()}.part")
    try:
        write(tmp)
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        problem = jpeg_problem(tmp)
        if problem is not None:
            raise PhotoWriteError(
                f"could not store photo {dest}: the file written {problem}; the disk may be "
                f"full ({space_left(dest)})"
            )
        publish(tmp, dest)
    except PhotoWriteError:
        raise
    except FileExistsError:
        raise PhotoWriteError(f"photo {dest} already exists: refusing to overwrite it") from None
    except OSError as exc:
        raise PhotoWriteError(
            f"could not store photo {dest}: {exc.strerror or exc} ({space_left(dest)})"
        ) from None
    finally:
        if os.path.lexists(tmp):
            tmp.unlink()  # a failed write's partial file: never a photo of the log
    return dest


def read_exif_focal(img: Image.Image) -> tuple[float | None, str]:
    """Focal length in pixels from an opened photo's EXIF, and where it came from.

    Order: FocalLength (mm) times FocalPlaneXResolution (px per unit, exact for the simulator
    and most cameras), else FocalLengthIn35mmFilm scaled by the image diagonal (the 35 mm
    definition uses the 43.27 mm diagonal). pycolmap's own EXIF reader uses only the 35 mm
    value or a sensor database, so SfM sets its camera prior from this function.

    Returns:
        ``(focal_px, source)`` with source ``exif_focal_plane`` or ``exif_35mm``;
        ``(None, "none")`` when EXIF has no usable focal length.
    """
    ifd = img.getexif().get_ifd(EXIF_IFD)
    w, h = img.size
    f_mm = _as_float(ifd.get(TAG_FOCAL_LENGTH))
    xres = _as_float(ifd.get(TAG_FOCAL_PLANE_XRES))
    unit = ifd.get(TAG_FOCAL_PLANE_UNIT, 2) or 2
    mm_per_unit = {2: 25.4, 3: 10.0, 4: 1.0, 5: 0.001}.get(int(unit))
    if f_mm > 0 and xres > 0 and mm_per_unit:
        return f_mm * xres / mm_per_unit, "exif_focal_plane"
    f35 = _as_float(ifd.get(TAG_FOCAL_35MM))
    if f35 > 0:
        return f35 / FULL_FRAME_DIAGONAL_MM * math.hypot(w, h), "exif_35mm"
    return None, "none"


def _as_float(v) -> float:
    try:
        x = float(v)
    except (TypeError, ValueError, ZeroDivisionError):
        return float("nan")
    return x if math.isfinite(x) else float("nan")


def exif_focal_px(path: Path) -> float | None:
    """Focal length in pixels from a JPEG file's EXIF (see :func:`read_exif_focal`)."""
    with Image.open(path) as im:
        return read_exif_focal(im)[0]
