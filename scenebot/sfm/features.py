"""SIFT features and matches in one persistent COLMAP database per scene.

The database (``results/{scene}/sfm_db/database.db`` in the workflow) keeps the keypoints,
descriptors and verified matches of every photo processed so far: a later round extracts
features only for its new photos and matches only pairs not matched before.
"""

from __future__ import annotations

import hashlib
import json
import logging
import time
from pathlib import Path

import pycolmap

from scenebot.sfm.config import SfmConfig
from scenebot.sfm.photos import Photo

log = logging.getLogger(__name__)


def open_database(path: Path) -> pycolmap.Database:
    """Open (or create) the COLMAP database at ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return pycolmap.Database.open(str(path))


def database_cache(db_path: Path, names, min_num_matches: int) -> pycolmap.DatabaseCache:
    """The database's photos of ``names`` and their verified pairs of at least
    ``min_num_matches`` inliers, loaded for an incremental mapper."""
    with open_database(db_path) as db:
        opts = pycolmap.DatabaseCacheOptions()
        opts.min_num_matches = min_num_matches
        opts.image_names = set(names)
        return pycolmap.DatabaseCache.create(db, opts)


def _sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def check_database_photos(db_path: Path, photos: list[Photo]) -> bool:
    """Make sure the database's features belong to the photos as they are now.

    A sidecar ``<database>.photos.json`` records each processed photo's SHA-256. When a photo
    with a name already in the database has different content (a capture round was re-run),
    the database and sidecar are moved aside to ``<database>.stale`` and everything is
    extracted again (COLMAP databases cannot delete single images).

    Returns:
        ``True`` if the database was reset.
    """
    db_path = Path(db_path)
    side = db_path.with_name(db_path.name + ".photos.json")
    known = json.loads(side.read_text()) if side.exists() else {}
    changed = [p.name for p in photos if p.name in known and known[p.name] != _sha256(p.path)]
    if not db_path.exists() or not changed:
        return False
    log.warning(
        "%d photo(s) changed since their features were extracted (%s); starting a new "
        "database, the old one is kept as %s.stale",
        len(changed),
        ", ".join(changed[:5]),
        db_path.name,
    )
    db_path.replace(db_path.with_name(db_path.name + ".stale"))
    side.unlink()
    return True


def _record_photos(db_path: Path, photos: list[Photo]) -> None:
    side = Path(db_path).with_name(Path(db_path).name + ".photos.json")
    known = json.loads(side.read_text()) if side.exists() else {}
    for p in photos:
        if p.name not in known:
            known[p.name] = _sha256(p.path)
    side.write_text(json.dumps(known, indent=0, sort_keys=True))


def _camera_key(p: Photo) -> tuple[int, int, float]:
    return (p.width, p.height, round(float(p.focal_px or 0.0), 3))


def extract(db_path: Path, image_root: Path, photos: list[Photo], cfg: SfmConfig) -> dict:
    """Extract SIFT features of the photos not yet in the database.

    Photos with the same size and EXIF focal share one camera (its focal as a prior, refined by
    bundle adjustment). Photos already in the database keep their features.

    Args:
        db_path: the scene's database.
        image_root: folder the photo names are relative to.
        photos: inspected photos (``width``, ``height``, ``focal_px`` set).
        cfg: sfm settings (features).

    Returns:
        ``{"new": n_extracted, "reused": n_already_in_db, "seconds": s}``.
    """
    t0 = time.perf_counter()
    with open_database(db_path) as db:
        existing = {im.name for im in db.read_all_images()}
        cams: dict[tuple[int, int, float], int] = {}
        for cam in db.read_all_cameras():
            if cam.has_prior_focal_length:
                key = (cam.width, cam.height, round(float(cam.params[0]), 3))
                cams.setdefault(key, cam.camera_id)
        new = [p for p in photos if p.name not in existing]
        groups: dict[tuple[int, int, float], list[Photo]] = {}
        for p in new:
            groups.setdefault(_camera_key(p), []).append(p)
        for key in groups:
            if key not in cams:
                w, h, f = key
                cam = pycolmap.Camera.create_from_model_name(0, cfg.camera_model, f, w, h)
                cam.has_prior_focal_length = True
                cams[key] = db.write_camera(cam)
    extraction = pycolmap.FeatureExtractionOptions()
    extraction.num_threads = cfg.num_threads
    extraction.max_image_size = cfg.max_image_size
    extraction.sift.max_num_features = cfg.max_num_features
    extraction.sift.domain_size_pooling = cfg.domain_size_pooling
    extraction.sift.peak_threshold = cfg.peak_threshold
    for key, group in groups.items():
        reader = pycolmap.ImageReaderOptions()
        reader.camera_model = cfg.camera_model
        reader.existing_camera_id = cams[key]
        pycolmap.extract_features(
            str(db_path),
            str(image_root),
            image_names=[p.name for p in group],
            camera_mode=pycolmap.CameraMode.SINGLE,
            reader_options=reader,
            extraction_options=extraction,
            device=pycolmap.Device.cpu,
        )
    with open_database(db_path) as db:
        missing = [
            p.name
            for p in new
            if (im := db.read_image_with_name(p.name)) is None
            or db.num_keypoints_for_image(im.image_id) == 0
        ]
    _record_photos(db_path, new)
    if missing:
        log.warning(
            "no SIFT features in %d photo(s) (blank or unreadable?): %s",
            len(missing),
            ", ".join(missing),
        )
    return {
        "new": len(new),
        "reused": len(photos) - len(new),
        "no_features": missing,
        "seconds": time.perf_counter() - t0,
    }


def match_pairs(db_path: Path, pairs: list[tuple[str, str]], cfg: SfmConfig, work: Path) -> dict:
    """Match and geometrically verify the given pairs of photo names, skipping matched ones.

    Args:
        db_path: the scene's database.
        pairs: photo-name pairs.
        cfg: sfm settings (matching).
        work: folder for the pair list file.

    Returns:
        ``{"requested": n, "new": n_matched_now, "seconds": s}``.
    """
    t0 = time.perf_counter()
    with open_database(db_path) as db:
        ids = {im.name: im.image_id for im in db.read_all_images()}
        todo = []
        seen = set()
        for a, b in pairs:
            if a not in ids or b not in ids or a == b:
                continue
            key = (min(ids[a], ids[b]), max(ids[a], ids[b]))
            if key in seen or db.exists_matches(*key):
                continue
            seen.add(key)
            todo.append((a, b))
    if todo:
        work.mkdir(parents=True, exist_ok=True)
        pair_file = work / "pairs.txt"
        pair_file.write_text("".join(f"{a} {b}\n" for a, b in todo))
        matching = pycolmap.FeatureMatchingOptions()
        matching.num_threads = cfg.num_threads
        pairing = pycolmap.ImportedPairingOptions()
        pairing.match_list_path = str(pair_file)
        verification = pycolmap.TwoViewGeometryOptions()
        verification.min_num_inliers = cfg.min_num_matches
        verification.ransac.random_seed = cfg.random_seed
        pycolmap.match_image_pairs(
            str(db_path),
            matching_options=matching,
            pairing_options=pairing,
            verification_options=verification,
            device=pycolmap.Device.cpu,
        )
    return {"requested": len(pairs), "new": len(todo), "seconds": time.perf_counter() - t0}
