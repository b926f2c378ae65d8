"""The capture stage: outputs, logs, never losing photos, clear errors."""

from __future__ import annotations

import json
import stat

import pytest

from scenebot.capture.stage import run_capture
from scenebot.capturelog import read_log
from scenebot.config import validate_config
from scenebot.scene.loader import SceneLoadError
from scenebot.sim.world import StartPoseError


def small_cfg(**over):
    data = {
        "sim": {"camera": {"width": 80, "height": 60}},
        "exploration": {"photos": 8},
    }
    data.update(over)
    return validate_config(data)


def test_capture_writes_photos_log_and_picture(tmp_path):
    out = tmp_path / "round_000" / "capture"
    summary = run_capture(small_cfg(), out, progress=False)
    assert summary["photos"] == 8
    records = list(read_log(out / "log.jsonl"))
    assert records[0]["type"] == "session" and records[-1]["type"] == "end"
    photos = [r for r in records if r["type"] == "photo"]
    assert len(photos) == 8
    for p in photos:
        img = out / p["image"]
        assert img.is_file() and img.read_bytes()[:2] == b"\xff\xd8"
        assert not img.stat().st_mode & stat.S_IWUSR  # photos are read-only
        assert {"odometry", "compass_deg", "ultrasonic_cm", "truth"} <= p.keys()
    assert (out / "trajectory.png").stat().st_size > 10_000


def test_a_rerun_keeps_the_earlier_photos(tmp_path):
    out = tmp_path / "capture"
    run_capture(small_cfg(), out, progress=False)
    first = sorted(p.name for p in (out / "images").glob("*.jpg"))
    run_capture(small_cfg(seed=5), out, progress=False)
    kept = list((out / "superseded").glob("*/images/*.jpg"))
    assert sorted(p.name for p in kept) == first
    assert list((out / "superseded").glob("*/session.jsonl"))


def test_a_start_pose_inside_an_obstacle_stops_with_the_key_to_change(tmp_path):
    cfg = small_cfg(world={"builtin": "office", "start": {"x": 0.05, "y": 2.0}})  # in a wall
    with pytest.raises(StartPoseError, match=r"world\.start"):
        run_capture(cfg, tmp_path / "c", progress=False)


def test_a_missing_scene_file_stops_and_keeps_earlier_photos(tmp_path):
    out = tmp_path / "capture"
    run_capture(small_cfg(), out, progress=False)
    cfg = small_cfg(world={"builtin": None, "file": str(tmp_path / "missing.glb")})
    with pytest.raises(SceneLoadError, match=r"missing.glb not found"):
        run_capture(cfg, out, progress=False)
    assert len(list(out.rglob("*.jpg"))) == 8  # nothing deleted


def test_cli_reports_a_bad_config_value(tmp_path, capsys):
    from scenebot.cli import main

    params = json.dumps({"robot": "roomba"})
    assert main(["capture", "--params", params, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "robot" in err and "'sim'" in err
