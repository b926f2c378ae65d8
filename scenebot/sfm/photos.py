"""The photo set of an sfm run: photos of capture rounds or a bring-your-own folder.

Photos are only read, never modified, moved or deleted. Every photo is checked before
SfM touches it (a corrupt or truncated JPEG stops the run with a message naming it), and
its focal length is read from EXIF (see :func:`scenebot.jpeg.read_exif_focal`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

from PIL import Image, UnidentifiedImageError

from scenebot.capturelog import photo_records
from scenebot.jpeg import read_exif_focal

log = logging.getLogger(__name__)

JPEG_SUFFIXES = {".jpg", ".jpeg", ".JPG", ".JPEG"}


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
        localization: ``(x, y, theta)`` visual localization estimate (robot frame) or ``None``.
        truth: the simulator's true pose record (evaluation only), or ``None``.
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
    truth: dict | None = field(default=None, repr=False)


def inspect_photo(photo: Photo) -> None:
    """Decode ``photo`` completely (catches corrupt and truncated JPEGs) and read its EXIF.

    Fills ``width``, ``height``, ``focal_px``, ``focal_source``. The file is opened read-only.

    Raises:
        PhotoError: the file is missing, not a JPEG, corrupt or truncated.
    """
    if not photo.path.is_file():
        raise PhotoError(f"photo {photo.path} is missing")
    try:
        with Image.open(photo.path) as img:
            img.verify()
        with Image.open(photo.path) as img:
            img.load()  # a truncated file raises here ("image file is truncated")
            if img.format != "JPEG":
                raise PhotoError(f"{photo.path} is a {img.format} file, not a JPEG")
            photo.width, photo.height = img.size
            photo.focal_px, photo.focal_source = read_exif_focal(img)
    except (OSError, UnidentifiedImageError, SyntaxError) as exc:
        raise PhotoError(f"{photo.path}: corrupt or truncated JPEG ({exc})") from exc


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


def _pose3(d: dict | None) -> tuple[float, float, float] | None:
    if not d:
        return None
    try:
        return float(d["x"]), float(d["y"]), float(d["theta"])
    except (KeyError, TypeError, ValueError):
        return None


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
                    truth=rec.get("truth"),
                )
            )
    return root, photos


def photos_from_folder(folder: Path) -> tuple[Path, list[Photo]]:
    """Bring-your-own photos: every JPEG of ``folder`` (not recursive), sorted by name.

    No odometry, no compass; the order of file names is taken as capture order.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise PhotoError(f"photo folder {folder} does not exist (robot: photos)")
    files = sorted(p for p in folder.iterdir() if p.suffix in JPEG_SUFFIXES and p.is_file())
    photos = [Photo(name=p.name, path=p.resolve(), round=0, index=i) for i, p in enumerate(files)]
    return folder.resolve(), photos
