"""Round-0 photos of the default office give a map that meets the issue's accuracy figures."""

from __future__ import annotations

import math

import pytest

from scenebot.capture.stage import run_capture
from scenebot.capturelog import photo_records
from scenebot.config import validate_config


@pytest.mark.slow
def test_round0_of_the_default_office_registers_accurately(tmp_path):
    """The default config: 100 photos at 640x480, the sfm stage with the camera's lever arm
    (the mount the simulator's camera config describes). Acceptance: >= 95 % registered,
    median position error <= 1 cm, heading <= 0.5 deg, metric scale error <= 2 %."""
    from scenebot.sfm.stage import inputs_for_round, run

    cfg = validate_config({})
    cam = cfg.sim.camera
    sfm = cfg.sfm.model_copy(
        update={"camera_offset_m": math.hypot(cam.forward_offset_m, cam.lateral_offset_m)}
    )
    scene_dir = tmp_path / "office"
    run_capture(cfg, scene_dir / "round_000" / "capture", progress=False)
    assert len(photo_records(scene_dir / "round_000" / "capture" / "log.jsonl")) == 100
    inputs, outputs = inputs_for_round(scene_dir, 0)
    report = run(sfm, inputs, outputs)
    acc = report["accuracy"]
    print(
        f"registered {report['registered']}/{report['photos']}, position "
        f"{acc['position_error_m']['median'] * 100:.2f} cm, heading "
        f"{acc['heading_error_deg']['median']:.3f} deg, scale {acc['metric_scale_error']:.2%}"
    )
    assert report["photos"] == 100
    assert report["registered"] >= 95
    assert report["scale"]["source"] == "camera_lever_arm"
    assert acc["position_error_m"]["median"] <= 0.01
    assert acc["heading_error_deg"]["median"] <= 0.5
    assert acc["metric_scale_error"] <= 0.02
