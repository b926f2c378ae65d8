"""Tour stage end to end on a synthetic capture: frames, video, viewer files; bad inputs."""

from __future__ import annotations

import json
import os

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")

from pathlib import Path

import cv2
import numpy as np
import pytest

from scenebot.tour.camera import TourInputError
from scenebot.tour.config import TourConfig
from scenebot.tour.stage import TourInputs, TourOutputs, run
from tests.fixtures.tour import make_tour_dataset

FRAMES = 24


def small_cfg(**kw) -> TourConfig:
    base = {
        "width": 96,
        "height": 72,
        "taichi_arch": "cpu",
        "eval_holdout": 4,
        "path": {"frames": FRAMES},
        "viewer": {"viewpoints": 6, "overview_px": 200},
    }
    base.update(kw)
    return TourConfig.model_validate(base)


@pytest.fixture(scope="module")
def tour(tmp_path_factory):
    root = tmp_path_factory.mktemp("tour_stage")
    ds = make_tour_dataset(root / "capture", width=128, height=96, per_stop=10)
    out = root / "tour"
    summary = run(
        small_cfg(), TourInputs(ds.sparse_dir, ds.root, ds.dense_ply), TourOutputs(out), False
    )
    return out, summary, ds


def test_outputs(tour):
    out, summary, _ = tour
    frames = sorted((out / "frames").glob("frame_*.jpg"))
    assert len(frames) == summary["frames"] == FRAMES
    img = cv2.imread(str(frames[0]))
    assert img.shape == (72, 96, 3)
    assert img.mean() > 20  # a rendered room, not a black frame
    for name in ("index.html", "viewer.js", "viewer.css", "tour_data.js", "overview.png"):
        assert (out / name).is_file(), name
    cap = cv2.VideoCapture(str(out / "tour.mp4"))
    n = 0
    while cap.read()[0]:
        n += 1
    assert n == FRAMES
    s = json.loads((out / "tour_summary.json").read_text())
    assert s["video_codec"] in ("h264", "mp4v")
    assert s["mean_coverage"] > 0.9
    # black pixels per frame in the summary; none in a closed room the photos saw
    assert len(s["black_fraction_per_frame"]) == FRAMES
    assert s["max_black_fraction"] == 0.0 and s["eval"]["mean_black_fraction"] == 0.0
    assert abs(sum(s["mean_fill_fractions"].values()) - 1) < 1e-6
    assert (out / "tour_path.png").is_file()
    assert not s["photos"] and s["length_unit"] == "m"
    assert s["eval"]["n_holdout"] == 4
    assert s["eval"]["mean_psnr_ulr"] > s["eval"]["mean_psnr_nearest"]


def test_viewer_data(tour):
    out, _, _ = tour
    text = (out / "tour_data.js").read_text()
    data = json.loads(text[text.index("=") + 1 :].strip().rstrip(";"))
    assert len(data["frames"]) == len(data["path_px"]) == len(data["headings"]) == FRAMES
    assert all((out / f).is_file() for f in data["frames"])
    assert 2 <= len(data["viewpoints"]) <= 6
    w, h = data["overview"]["width"], data["overview"]["height"]
    px = np.array(data["path_px"])
    assert (px >= 0).all() and (px[:, 0] < w).all() and (px[:, 1] < h).all()


def test_frames_are_consistent_with_the_scene(tour):
    # frame 0 against a true render of the same pose
    from scenebot.testing import dense as syn
    from scenebot.tour.camera import Camera, look_rotation
    from scenebot.tour.evaluate import psnr

    out, summary, ds = tour
    data = json.loads((out / "tour_data.js").read_text().split("=", 1)[1].strip().rstrip(";"))
    i = 5
    pos = np.array(data["positions_m"][i])
    R = look_rotation(data["headings"][i])
    cam = Camera.pinhole(96, 72, summary["hfov_deg"])
    fx, fy, cx, cy = cam.params[:4]
    K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])
    truth, _, _ = syn.render_view(ds.scene, K, R, -R @ pos, 96, 72)
    frame = cv2.cvtColor(cv2.imread(str(out / data["frames"][i])), cv2.COLOR_BGR2RGB)
    assert psnr(frame, truth) > 22.0


def test_empty_cloud_is_a_clear_error(tmp_path, tour):
    _, _, ds = tour
    ply = tmp_path / "empty.ply"
    ply.write_text("ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\n"
                   "property float y\nproperty float z\nend_header\n")  # fmt: skip
    with pytest.raises(TourInputError, match=r"empty\.ply.*tour\.proxy\.min_points"):
        run(small_cfg(), TourInputs(ds.sparse_dir, ds.root, ply), TourOutputs(tmp_path / "o"))
    with pytest.raises(TourInputError, match="run the dense stage"):
        run(
            small_cfg(),
            TourInputs(ds.sparse_dir, ds.root, tmp_path / "missing.ply"),
            TourOutputs(tmp_path / "o"),
        )


def test_no_valid_pose_is_a_clear_error(tmp_path, tour):
    _, _, ds = tour
    cfg = small_cfg(path={"frames": 8, "clearance_m": 10.0})
    with pytest.raises(TourInputError, match="clearance_m"):
        run(cfg, TourInputs(ds.sparse_dir, ds.root, ds.dense_ply), TourOutputs(tmp_path / "o"))


def test_missing_model_is_a_clear_error(tmp_path, tour):
    _, _, ds = tour
    with pytest.raises(TourInputError, match="run the sfm stage"):
        run(
            small_cfg(),
            TourInputs(tmp_path, ds.root, ds.dense_ply),
            TourOutputs(tmp_path / "o"),
        )


def test_stage_writes_only_below_its_folder(tour):
    # the stage writes everything below its folder and nothing else
    out, _, _ = tour
    assert all(Path(p).resolve().is_relative_to(out.resolve()) for p in out.rglob("*"))
