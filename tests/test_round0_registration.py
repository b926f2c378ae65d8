"""Round-0 photos of the default office are good enough for structure from motion."""

from __future__ import annotations

import pytest

from scenebot.capture import run_capture
from scenebot.capturelog import photo_records
from scenebot.config import validate_config


@pytest.mark.slow
def test_at_least_90_percent_of_a_random_exploration_registers(tmp_path):
    """The default config: 100 photos at 640x480, pycolmap incremental mapping (sfm stage)."""
    from scenebot.sfm.stage import inputs_for_round, run

    cfg = validate_config({})
    scene_dir = tmp_path / "office"
    run_capture(cfg, scene_dir / "round_000" / "capture", progress=False)
    assert len(photo_records(scene_dir / "round_000" / "capture" / "log.jsonl")) == 100
    inputs, outputs = inputs_for_round(scene_dir, 0)
    report = run(cfg.sfm, inputs, outputs)
    print(f"registered {report['registered']}/{report['photos']} photos")
    assert report["photos"] == 100
    assert report["registered"] >= 90
