"""The tour on a person's real photos: the Middlebury temple ring (16 photos, all register).

The workflow (``robot: photos``, every target; dense at 224 px) on a copy of the photos,
checked against the set's calibrated cameras and the object's bounding box (mapped into the
map's frame by a similarity fit of the camera centres; evaluation only):
every tour frame shows the object, no black pixel inside the object's projected box (tour
frames and held-out views), and leave-one-out ULR beats the nearest photo.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")

import numpy as np
import pytest

TEMPLE = Path(__file__).resolve().parent / "data" / "temple"  # as JPEG (README there)
BOX_LO = (-0.073568, 0.021728, -0.012445)  # README of the set, its frame (metres)
BOX_HI = (0.028855, 0.181892, 0.062736)

pytestmark = pytest.mark.slow


TOUR = {
    "width": 320,
    "height": 240,
    "taichi_arch": "cpu",
    "eval_holdout": 16,
    "path": {"frames": 24},
    "viewer": {"overview_px": 200},
}


@pytest.fixture(scope="module")
def temple(tmp_path_factory):
    """``snakemake --cores 2`` with ``robot: photos`` on a copy of the temple photos, every
    target (small dense and tour settings), evaluated against the set's cameras and box."""
    import yaml

    from scenebot.tour.config import TourConfig
    from scenebot.tour.stage import TourInputs
    from tests.test_workflow import snakemake, why

    root = tmp_path_factory.mktemp("temple")
    photos = root / "photos"
    photos.mkdir()
    for f in sorted(TEMPLE.glob("*.jpg")):
        shutil.copy(f, photos / f.name)  # never touch the set itself
    before = {p.name: p.read_bytes() for p in photos.iterdir()}
    cfg = {
        "scene": "temple",
        "robot": "photos",
        "photos": {"folder": str(photos)},
        # the tape measure: templeSR0001 to templeSR0012 (examples/temple.yaml)
        "sfm": {
            "known_distance": {
                "image_a": "templeSR0001.jpg",
                "image_b": "templeSR0012.jpg",
                "distance_m": 1.122,
            }
        },
        "score": {"n_candidates": 400},
        "goals": {"k": 3},
        "dense": {"max_image_size": 224, "plane_fill": {"enabled": False}},
        "tour": TOUR,
        "evaluate": {
            "reference_cameras": str(TEMPLE / "templeSR_par.txt"),
            "reference_bbox": [list(BOX_LO), list(BOX_HI)],
        },
    }
    (root / "config.yaml").write_text(yaml.safe_dump(cfg))
    res = snakemake(root)
    assert res.returncode == 0, why(res, root)
    results = root / "results" / "temple"
    summary = json.loads((results / "final/tour/tour_summary.json").read_text())
    inputs = TourInputs(
        results / "round_000/sfm", photos, results / "final/dense/fused.ply", photos=True
    )
    return root, inputs, TourConfig.model_validate(TOUR), summary, results, before


def test_every_stage_runs_on_a_persons_photos(temple):
    """The workflow on real photos of an object: all 16 register, the camera centres within
    millimetres of the calibrated ones, the dense model on the object, advice that is not
    "complete", the photos unchanged."""
    root, _, _, _, results, before = temple
    ev = json.loads((results / "final/evaluation.json").read_text())
    assert ev["reference"]["cameras"] == 16 and ev["reference"]["registered"] == 16
    assert ev["reference"]["centre_error"]["median"] < 0.002  # metres; 0.9 mm measured
    assert ev["alignment"]["scale"] == pytest.approx(1.0, abs=0.02)  # known_distance: metric
    assert ev["dense"]["near_bbox"] > 0.25  # the rest: the cloth and stand around it
    goals = json.loads((results / "round_000/goals.json").read_text())
    assert goals["complete"] is False and goals["goals"]
    assert all({"z", "pitch"} <= g.keys() for g in goals["goals"])
    assert (results / "round_000/goals.png").stat().st_size > 10_000
    campaign = json.loads((results / "campaign.json").read_text())
    assert [r["round"] for r in campaign["rounds"]] == [0]
    assert {p.name: p.read_bytes() for p in (root / "photos").iterdir()} == before


def test_tour_runs_on_a_persons_photos(temple):
    _, _, _, s, results, _ = temple
    assert s["photos"] and s["length_unit"] == "model units"
    assert s["frames"] >= 22  # at most a tenth of the path dropped
    assert s["path_max_turn_deg"] <= 2 * max(3.0, 360 / s["frames"])
    assert len(s["black_fraction_per_frame"]) == s["frames"]
    assert s["mean_black_fraction"] < 0.01
    assert (results / "final/tour/tour_path.png").is_file()
    data = (results / "final/tour/tour_data.js").read_text()
    assert len(json.loads(data.split("=", 1)[1].strip().rstrip(";"))["frames"]) == s["frames"]


def test_object_in_view_and_no_black_pixel_on_it(temple):
    from scenebot.testing.photos import box_in_map, box_rect, read_middlebury_cameras
    from scenebot.tour.stage import build_renderer, plan_valid_path, tour_camera
    from scenebot.tour.ulr import FILL_NONE

    _, inputs, cfg, _, _, _ = temple
    renderer, _ = build_renderer(cfg, inputs)
    given = read_middlebury_cameras(TEMPLE / "templeSR_par.txt")
    names = [s.name for s in renderer.sources]
    corners, fit = box_in_map(names, renderer.centers, given, BOX_LO, BOX_HI)
    assert fit < 0.02  # the map's cameras agree with the calibrated ones
    path = plan_valid_path(renderer.cfg, renderer, None, photos=True)
    cam = tour_camera(renderer.cfg, renderer.sources[0].camera)
    centre = corners.mean(0)
    for i in range(0, len(path), 3):
        R, t = path.pose(i)
        # the object's centre is within 10 degrees of the view's axis, well inside the view
        # (the photos' own field of view is 23 degrees wide)
        to_obj = centre - path.positions[i]
        cos = to_obj @ R[2] / np.linalg.norm(to_obj)
        assert np.degrees(np.arccos(min(cos, 1.0))) < 10.0, i
        uv = cam.project((R @ centre + t)[None])[0]
        assert 0.1 * cam.width < uv[0] < 0.9 * cam.width, i
        assert 0.1 * cam.height < uv[1] < 0.9 * cam.height, i
        box = box_rect(cam, R, t, corners)
        res = renderer.render(cam, R, t)
        assert not (box & (res.fill == FILL_NONE)).any(), i
    for j, s in list(enumerate(renderer.sources))[::2]:  # held-out views too
        box = box_rect(s.camera, s.R, s.t, corners)
        res = renderer.render(s.camera, s.R, s.t, exclude={j})
        assert box is not None and box.any()
        assert not (box & (res.fill == FILL_NONE)).any(), s.name


def test_leave_one_out_beats_the_nearest_photo(temple):
    _, _, _, s, _, _ = temple
    ev = s["eval"]
    assert ev["n_holdout"] >= 12
    assert ev["median_psnr_ulr"] > ev["median_psnr_nearest"] + 3.0
    assert ev["mean_psnr_ulr"] > ev["mean_psnr_nearest"] + 2.0
    assert ev["mean_black_fraction"] == 0.0
    assert np.isfinite(ev["mean_ssim_ulr"])
