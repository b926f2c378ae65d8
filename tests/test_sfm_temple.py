"""Bring-your-own photos on real photos with calibrated cameras: the Middlebury temple ring
(16 photos, 640x480, no EXIF, rolled 90 or 180 degrees; tests/data/temple, as JPEG), copied to
a temporary folder.

One run of the benchmark's comparison (benchmarks/bench_byo_sfm.py): the sfm stage with the
default settings against plain pycolmap with one shared camera (the stronger of its two
references), errors in millimetres after a similarity fit to the given cameras.
"""

from __future__ import annotations

import importlib.util
import json
import math
import sys
from pathlib import Path

import numpy as np
import pycolmap
import pytest

from scenebot.sfm.evaluate import umeyama
from scenebot.sfm.person_frame import SCALE_UNKNOWN, person_frame_transform
from scenebot.sfm.photos import Photo

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data" / "temple"  # the 16 photos as JPEG (README there), in CI too
DROPPED_BY_INCREMENTAL = ["templeSR0003.jpg", "templeSR0004.jpg", "templeSR0014.jpg"]


def _bench():
    spec = importlib.util.spec_from_file_location(
        "bench_byo_sfm", ROOT / "benchmarks" / "bench_byo_sfm.py"
    )
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


BENCH = _bench()
pytestmark = pytest.mark.slow  # about 30 s on 2 cores: two SfM runs of 16 photos


@pytest.fixture(scope="module")
def temple(tmp_path_factory):
    data = DATA
    before = {p.name: p.stat().st_mtime_ns for p in data.iterdir()}
    res = BENCH.compare(data, tmp_path_factory.mktemp("temple"), ("pycolmap_single",))
    assert {p.name: p.stat().st_mtime_ns for p in data.iterdir()} == before  # only copied
    res["rec"] = pycolmap.Reconstruction(str(res["model_dir"]))
    res["given"] = BENCH.read_par(data / BENCH.PAR_FILE)
    return res


def test_all_16_photos_register_with_the_default_settings(temple):
    """The incremental mapper leaves out the three photos across the ring's widest gaps
    (they see 5-21 triangulated points, < 30); global SfM, run because verified pairs
    connect them to the model, registers all 16 and is kept."""
    rep = temple["report"]
    assert rep["photos"] == 16 and rep["registered"] == 16 and rep["dropped"] == {}
    assert rep["mapper"] == "global"
    g = rep["global_sfm"]
    assert g["kept"] == "global" and g["global_registered"] == 16
    assert g["disagreement"] < 0.01  # the two models agree on the photos both registered
    assert g["incremental_registered"] < 16
    assert set(g["left_out"]) <= set(DROPPED_BY_INCREMENTAL)


def test_camera_centres_at_least_as_accurate_as_plain_pycolmap(temple):
    ours, ref = temple["scenebot"], temple["pycolmap_single"]
    assert ours["registered"] == 16 and ours["registered"] > ref["registered"]
    assert ours["median_mm"] <= ref["median_mm"]
    assert ours["median_mm"] < 1.5 and ours["max_mm"] < 8.0  # measured 0.89 and 4.65 mm


def _fit_to_given(rec, given):
    ims = [rec.image(i) for i in rec.reg_image_ids()]
    src = np.array([im.projection_center() for im in ims])
    dst = np.array([given[im.name] for im in ims])
    return umeyama(src, dst), src


def test_up_comes_from_the_photos_despite_their_roll(temple):
    """The image-up vectors are all horizontal (photos rolled 90 or 180 degrees): up comes
    from the optical axes and camera positions, its sign from the cameras looking down; the
    map's z axis is the given +y within 3 degrees (the gantry's ring is tilted ~2 degrees in
    the given frame: both cues agree on its axis)."""
    rec, rep = temple["rec"], temple["report"]
    (_, R, _), src = _fit_to_given(rec, temple["given"])
    up_in_given = R @ np.array([0.0, 0.0, 1.0])
    assert math.degrees(math.acos(np.clip(up_in_given[1], -1, 1))) < 3.0
    stats = rep["alignment"]["stats"]
    up = stats["up"]
    assert up["source"] == "photos" and up["sign_source"] == "cameras_look_down"
    assert not up["image_up_informative"] and abs(up["image_up_mean"]) < 0.1
    assert up["optical_axes"]["determines_axis"] and up["camera_centres"]["determines_axis"]
    assert up["cues_angle_deg"] < 2.0
    assert -15.0 < up["mean_view_elevation_deg"] < -3.0  # the gantry looks slightly down
    # the frame: z = 0 at the median camera height, origin below the centroid, x along the
    # first photo's view; SfM units, said in the log and report
    assert np.median(src[:, 2]) == pytest.approx(0.0, abs=1e-9)
    assert np.allclose(src[:, :2].mean(0), 0.0, atol=1e-9)
    first = next(i for i in rec.reg_image_ids() if rec.image(i).name == "templeSR0001.jpg")
    view = rec.image(first).cam_from_world().rotation.matrix()[2]
    assert abs(view[1]) < 1e-9 and view[0] > 0
    assert rep["alignment"]["scale_source"] == "none" and SCALE_UNKNOWN in rep["warnings"]
    assert json.loads((temple["model_dir"] / "report.json").read_text())["warnings"]


def test_a_known_distance_makes_the_map_metric(temple):
    """sfm.known_distance between two camera centres (examples/temple.yaml's tape measure):
    every distance between camera centres matches the given cameras within 1 %."""
    rec, given = temple["rec"], temple["given"]
    a, b = "templeSR0001.jpg", "templeSR0012.jpg"
    fit = person_frame_transform(
        rec,
        [Photo(name=n, path=Path(n)) for n in sorted(given)],
        known_distance=(a, b, float(np.linalg.norm(given[a] - given[b]))),
        up_photo=None,
    )
    assert fit.scale_source == "known_distance" and SCALE_UNKNOWN not in fit.stats["warnings"]
    ims = [rec.image(i) for i in rec.reg_image_ids()]
    X = fit.scale * np.array([im.projection_center() for im in ims]) @ fit.R.T + fit.t
    G = np.array([given[im.name] for im in ims])
    i, j = np.triu_indices(len(ims), 1)
    ratio = np.linalg.norm(X[i] - X[j], axis=1) / np.linalg.norm(G[i] - G[j], axis=1)
    ok = np.linalg.norm(G[i] - G[j], axis=1) > 0.1  # 0001 and 0011 share a centre
    assert np.median(ratio[ok]) == pytest.approx(1.0, abs=0.01)


def test_photos_of_an_unrelated_scene_are_named_and_left_out(tmp_path, caplog):
    """The temple's 16 photos and 3 photos of the office in one folder: the map is the
    temple, the office photos are named (log and report) with the reason, and nothing in
    the folder changes."""
    import hashlib
    import logging
    import shutil

    from scenebot.sfm.config import SfmConfig
    from scenebot.sfm.stage import SfmInputs, SfmOutputs, run

    folder = tmp_path / "mixed"
    folder.mkdir()
    for p in sorted(DATA.glob("*.jpg")):
        shutil.copy(p, folder / p.name)
    office = sorted((ROOT / "tests/data/canned/round_000/capture/images").glob("*.jpg"))[:3]
    for p in office:
        shutil.copy(p, folder / f"office_{p.name}")
    digest = {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in folder.iterdir()}
    with caplog.at_level(logging.WARNING):
        rep = run(
            SfmConfig(num_threads=1),  # one thread: the same map every run
            SfmInputs(tmp_path / "db.db", photo_folder=folder),
            SfmOutputs(tmp_path / "sfm"),
        )
    others = {f"office_{p.name}" for p in office}
    assert rep["photos"] == 19 and rep["registered"] == 16
    assert set(rep["dropped"]) == others and all(rep["dropped"].values())
    assert all(name in caplog.text for name in others)
    assert {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in folder.iterdir()} == digest
