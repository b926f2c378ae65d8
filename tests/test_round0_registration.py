"""Round-0 photos of the default office are good enough for structure from motion."""

from __future__ import annotations

import pytest

from scenebot.capture import run_capture
from scenebot.capturelog import photo_records
from scenebot.config import validate_config


@pytest.mark.slow
def test_pycolmap_registers_at_least_90_percent_of_a_random_exploration(tmp_path):
    """100 photos at 640x480 (the default config), plain pycolmap: SIFT, exhaustive, mapping."""
    pycolmap = pytest.importorskip("pycolmap")
    out = tmp_path / "capture"
    run_capture(validate_config({}), out, progress=False)
    photos = photo_records(out / "log.jsonl")
    assert len(photos) == 100
    db = tmp_path / "database.db"
    pycolmap.extract_features(db, out / "images", camera_mode=pycolmap.CameraMode.SINGLE)
    pycolmap.match_exhaustive(db)
    models = pycolmap.incremental_mapping(db, out / "images", tmp_path / "sparse")
    best = max(models.values(), key=lambda r: r.num_reg_images())
    registered = best.num_reg_images()
    print(f"registered {registered}/100 photos, {best.num_points3D()} points")
    assert registered >= 90
