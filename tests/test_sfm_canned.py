"""The sfm stage on the committed canned photo set (45 photos of the simulated office, 320x240).

Made by ``tests/data/make_canned.py`` through the capture stage; the log's ``truth`` is used
only by the evaluation. Tolerances are for 320x240 photos and two odometry drives (the
acceptance figures are measured at 640x480 by benchmarks/bench_sfm.py).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pycolmap
import pytest

from scenebot.sfm.config import SfmConfig
from scenebot.sfm.stage import SfmInputs, SfmOutputs, run

CANNED = Path(__file__).parent / "data" / "canned" / "round_000" / "capture"


@pytest.mark.slow
@pytest.mark.skipif(not (CANNED / "log.jsonl").exists(), reason="canned set not generated")
def test_canned_office_round0(tmp_path):
    cap = tmp_path / "scene" / "round_000" / "capture"
    shutil.copytree(CANNED, cap)
    out = SfmOutputs(tmp_path / "scene" / "round_000" / "sfm")
    # small photos: more SIFT features; one thread makes mapping repeatable (with several
    # threads the 320x240 set occasionally bent by ~15 cm in CI: a known fragility)
    cfg = SfmConfig(peak_threshold=0.002, num_threads=1)
    report = run(cfg, SfmInputs(tmp_path / "scene" / "sfm_db" / "database.db", [cap]), out)
    assert report["registered"] >= 0.9 * report["photos"]
    assert report["alignment"]["scale_source"] == "odometry"
    acc = json.loads(out.accuracy.read_text())
    # the set has two drives (two and a half circles): a coarse metric scale only
    assert acc["metric_scale_error"] < 0.5
    assert acc["position_error_m"]["median"] < 0.08
    assert acc["heading_error_deg"]["median"] < 1.0
    rec = pycolmap.Reconstruction(str(out.model_dir))
    z = np.array([rec.image(i).projection_center()[2] for i in rec.reg_image_ids()])
    assert np.median(np.abs(z)) < 0.08  # 320x240: the model bends by centimetres
    d = np.load(out.descriptors)
    assert len(d["point_ids"]) == sum(p.track.length() for p in rec.points3D.values())
