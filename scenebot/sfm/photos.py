"""The photo set of an sfm run: photos of capture rounds or a bring-your-own folder.

Photos are only read, never modified, moved or deleted. Every photo is checked before
SfM touches it (an empty, corrupt or truncated file, or one that is not an 8-bit JPEG or PNG,
stops the run with a message naming it), and its focal length is read from EXIF (see
:func:`scenebot.jpeg.read_exif_focal`). Which files of a folder are photos, and their
order, is defined once in :mod:`scenebot.sfm.photofiles` (the workflow uses it too).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from PIL import Image, UnidentifiedImageError

from scenebot.capturelog import photo_records, read_log
from scenebot.jpeg import read_exif_focal
from scenebot.sfm.photofiles import other_files, photo_files, sha256_of

log = logging.getLogger(__name__)

PHOTO_FORMATS = ("JPEG", "PNG")
"""Image formats SfM reads (PIL's names; by content, whatever the suffix)."""
DEEP_MODES = ("I", "I;16", "I;16B", "I;16L", "I;16N", "F")
"""PIL modes of 16-bit and float images: COLMAP finds no features in them."""


@dataclass(frozen=True)
class Motion:
    """A camera pose the camera's own motion tracking recorded (a phone's visual-inertial
    odometry: the log's ``motion``), in the frame of one tracking session.

    Attributes:
        session: the session's name; poses of two sessions are not comparable.
        center: (3,) camera centre (m) in the session's frame.
        rotation: (3, 3) cam_from_session rotation.
        walked_m: length of the session's track up to this photo (m).
    """

    session: str
    center: np.ndarray
    rotation: np.ndarray
    walked_m: float


class PhotoError(ValueError):
    """A photo set that SfM cannot use; the message names the photos and the fix."""


@dataclass
class Photo:
    """One photo of the set.

    Attributes:
        name: path relative to the image root (the COLMAP image name), e.g.
            ``round_000/capture/images/r000_0003.jpg``.
        path: absolute path of the JPEG.
        round: capture round (0 for bring-your-own photos).
        index: order of capture within the round.
        width, height: image size (px).
        focal_px: focal length (px) from EXIF, or ``None`` when EXIF has none.
        focal_source: how ``focal_px`` was found (``exif_focal_plane``, ``exif_35mm``, ``none``).
        odometry: ``(x, y, theta)`` (m, m, rad) in the round's odometry frame, or ``None``.
        compass_deg: compass heading (deg, counter-clockwise) or ``None``.
        localization: ``(x, y, theta)`` the robot's own map-frame estimate (robot frame) or
            ``None``: its visual fix of this photo, or the last fix carried by odometry.
        localization_fix: ``localization`` is a visual fix of this very photo (the log's
            ``localization_source`` is ``this photo``, or absent).
        orientation: ``(heading, pitch, roll)`` (deg) the camera's own sensors recorded
            (a phone's compass and accelerometer: the log's ``orientation``), or ``None``.
        motion: the camera's own tracking of its pose (:class:`Motion`), or ``None``.
        truth: the simulator's true pose record (evaluation only), or ``None``.
        source: where a person's photo was taken in from (the log's ``source``: a file of
            ``photos.folder`` or of the round's inbox), or ``None``.
    """

    name: str
    path: Path
    round: int = 0
    index: int = 0
    width: int = 0
    height: int = 0
    focal_px: float | None = None
    focal_source: str = "none"
    odometry: tuple[float, float, float] | None = None
    compass_deg: float | None = None
    localization: tuple[float, float, float] | None = None
    localization_fix: bool = False
    orientation: tuple[float, float, float] | None = None
    motion: Motion | None = field(default=None, repr=False)
    truth: dict | None = field(default=None, repr=False)
    source: str | None = None


def inspect_photo(photo: Photo) -> None:
    """Decode ``photo`` completely (catches corrupt and truncated files) and read its EXIF.

    Fills ``width``, ``height``, ``focal_px``, ``focal_source``. The file is opened read-only.

    Raises:
        PhotoError: the file is missing, empty, not a JPEG or PNG, 16-bit, corrupt or
            truncated; the message starts with its path.
    """
    if not photo.path.is_file():
        raise PhotoError(f"photo {photo.path} is missing")
    if photo.path.stat().st_size == 0:
        raise PhotoError(f"{photo.path}: empty file (0 bytes)")
    try:
        with Image.open(photo.path) as img:
            img.verify()
        with Image.open(photo.path) as img:
            img.load()  # a truncated file raises here ("image file is truncated")
            fmt, mode = img.format, img.mode
            photo.width, photo.height = img.size
            photo.focal_px, photo.focal_source = read_exif_focal(img)
    except (OSError, UnidentifiedImageError, SyntaxError, ValueError) as exc:
        raise PhotoError(f"{photo.path}: not an image, or corrupt or truncated ({exc})") from exc
    if fmt not in PHOTO_FORMATS:
        raise PhotoError(
            f"{photo.path}: a {fmt} file; photos must be JPEG or PNG (convert it, or move it "
            "out of the folder)"
        )
    if mode in DEEP_MODES:
        raise PhotoError(
            f"{photo.path}: a {fmt} of 16 bits or floats per pixel (mode {mode}), which "
            "structure from motion cannot read; save it with 8 bits per channel"
        )


def check_photos(photos: list[Photo], fallback_focal_factor: float) -> None:
    """Inspect all photos; collect every bad one into one clear error.

    Photos without an EXIF focal get ``fallback_focal_factor * max(width, height)`` and a
    log message naming them.

    Raises:
        PhotoError: fewer than 3 photos, or any corrupt/truncated photo (all named).
    """
    if len(photos) < 3:
        names = ", ".join(str(p.path) for p in photos) or "none"
        raise PhotoError(
            f"structure from motion needs at least 3 photos, got {len(photos)} ({names}); "
            "add photos to the folder or capture round"
        )
    bad: list[str] = []
    for p in photos:
        try:
            inspect_photo(p)
        except PhotoError as exc:
            bad.append(str(exc))
    if bad:
        raise PhotoError(
            f"{len(bad)} unusable photo(s):\n  "
            + "\n  ".join(bad)
            + "\nMove or replace them (scenebot never modifies photos) and run again."
        )
    no_focal = [p for p in photos if p.focal_px is None]
    for p in no_focal:
        p.focal_px = fallback_focal_factor * max(p.width, p.height)
        p.focal_source = "fallback"
    if no_focal:
        log.warning(
            "%d photo(s) have no EXIF focal length; assuming %.3g x longest side "
            "(sfm.fallback_focal_factor), refined by bundle adjustment: %s",
            len(no_focal),
            fallback_focal_factor,
            ", ".join(p.name for p in no_focal[:20]) + (" ..." if len(no_focal) > 20 else ""),
        )


def _three(d: dict | None, keys: tuple[str, str, str]) -> tuple[float, float, float] | None:
    """The three numbers of ``d`` under ``keys``, or None when one is missing or not one."""
    if not d:
        return None
    try:
        a, b, c = (float(d[k]) for k in keys)
    except (KeyError, TypeError, ValueError):
        return None
    return a, b, c


def _pose3(d: dict | None) -> tuple[float, float, float] | None:
    """A logged robot pose (``x``, ``y``, ``theta``), or None."""
    return _three(d, ("x", "y", "theta"))


def _orientation(d: dict | None) -> tuple[float, float, float] | None:
    """The log's ``orientation`` (``heading_deg``, ``pitch_deg``, ``roll_deg``), or None."""
    return _three(d, ("heading_deg", "pitch_deg", "roll_deg"))


def _motion(d: dict | None) -> Motion | None:
    """The log's ``motion`` (``session``, ``center``, ``R_cam_from_session``, ``walked_m``),
    or None when it is missing or malformed (a rotation that is not one)."""
    if not isinstance(d, dict):
        return None
    try:
        c = np.asarray(d["center"], float).reshape(3)
        R = np.asarray(d["R_cam_from_session"], float).reshape(3, 3)
        walked = float(d.get("walked_m", 0.0))
        session = str(d["session"])
    except (KeyError, TypeError, ValueError):
        return None
    if not (np.all(np.isfinite(c)) and np.allclose(R @ R.T, np.eye(3), atol=1e-3)):
        return None
    return Motion(session, c, R, walked)


def image_root_of(capture_dirs: list[Path]) -> Path:
    """The image root of capture rounds: the scene folder that holds ``round_*/capture``.

    Raises:
        PhotoError: the capture folders do not share one scene folder.
    """
    roots = {Path(d).resolve().parent.parent for d in capture_dirs}
    if len(roots) != 1:
        raise PhotoError(
            "capture folders must be round_*/capture folders of one scene folder, got "
            + ", ".join(str(d) for d in capture_dirs)
        )
    return roots.pop()


def photos_from_captures(capture_dirs: list[Path]) -> tuple[Path, list[Photo]]:
    """The photos of capture rounds, in round order.

    Args:
        capture_dirs: ``.../round_{k}/capture`` folders (each with ``log.jsonl`` and
            ``images/``), in round order.

    Returns:
        ``(image_root, photos)``: names are relative to ``image_root`` (the scene folder).
    """
    capture_dirs = [Path(d) for d in capture_dirs]
    root = image_root_of(capture_dirs)
    photos: list[Photo] = []
    for k, cap in enumerate(capture_dirs):
        log_path = cap / "log.jsonl"
        if not log_path.is_file():
            raise PhotoError(f"{log_path} is missing: is {cap} a finished capture round?")
        rel_cap = cap.resolve().relative_to(root)
        round_dir = cap.resolve().parent.name  # round_XXX
        rnd = int(round_dir[6:]) if round_dir[:6] == "round_" and round_dir[6:].isdigit() else k
        for rec in photo_records(log_path):
            path = (cap / rec["image"]).resolve()
            photos.append(
                Photo(
                    name=(rel_cap / rec["image"]).as_posix(),
                    path=path,
                    round=rnd,
                    index=int(rec.get("index", len(photos))),
                    odometry=_pose3(rec.get("odometry")),
                    compass_deg=(
                        float(rec["compass_deg"]) if rec.get("compass_deg") is not None else None
                    ),
                    localization=_pose3(rec.get("localization")),
                    localization_fix=_pose3(rec.get("localization")) is not None
                    and rec.get("localization_source", "this photo") == "this photo",
                    orientation=_orientation(rec.get("orientation")),
                    motion=_motion(rec.get("motion")),
                    truth=rec.get("truth"),
                    source=rec.get("source"),
                )
            )
    return root, photos


def logged_known_distance(capture_dirs: list[Path]) -> tuple[str, str, float] | None:
    """The first ``known_distance`` event of the capture logs (a person's tape measurement
    between where it took two photos: ``image_a``, ``image_b``, ``distance_m``) as
    ``(name_a, name_b, metres)`` with the map's photo names; None without one."""
    capture_dirs = [Path(d) for d in capture_dirs]
    if not capture_dirs:
        return None
    root = image_root_of(capture_dirs)
    for cap in capture_dirs:
        path = cap / "log.jsonl"
        if not path.is_file():
            continue
        rel = cap.resolve().relative_to(root)
        for rec in read_log(path):
            if rec.get("type") == "event" and rec.get("event") == "known_distance":
                return (
                    (rel / rec["image_a"]).as_posix(),
                    (rel / rec["image_b"]).as_posix(),
                    float(rec["distance_m"]),
                )
    return None


def photos_from_folder(folder: Path) -> tuple[Path, list[Photo]]:
    """Bring-your-own photos: every photo file of ``folder`` (not recursive; see
    :mod:`scenebot.sfm.photofiles` for which files are photos and their order).

    No odometry, no compass; the order of file names is taken as capture order. Other files
    are ignored (logged by name). A photo with the same bytes as an earlier one is left out
    (logged, naming both): the same view twice adds nothing to a map. Photos are only read.

    Raises:
        PhotoError: the folder does not exist.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise PhotoError(f"photo folder {folder} does not exist (robot: photos)")
    ignored = other_files(folder)
    if ignored:
        log.info(
            "%d file(s) of %s are not photos (.jpg, .jpeg or .png in any case) and are ignored: %s",
            len(ignored),
            folder,
            ", ".join(p.name for p in ignored[:20]) + (" ..." if len(ignored) > 20 else ""),
        )
    files: list[Path] = []
    first_of: dict[str, str] = {}
    for p in photo_files(folder):
        digest = sha256_of(p) if p.stat().st_size > 0 else None  # empty files: check_photos
        if digest is not None and digest in first_of:
            log.warning(
                "%s has the same bytes as %s (the same photo twice): left out of the map",
                p.name,
                first_of[digest],
            )
            continue
        if digest is not None:
            first_of[digest] = p.name
        files.append(p)
    photos = [Photo(name=p.name, path=p.resolve(), round=0, index=i) for i, p in enumerate(files)]
    return folder.resolve(), photos
