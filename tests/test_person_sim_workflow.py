"""A small guided campaign of the simulated person (``robot: person-sim``) through the
workflow: round 0 its walk along the office's walls, round 1 the shots of round 0's guide,
taken into the map from round 1's inbox; checked against the simulator's truth."""

from __future__ import annotations

import hashlib
import json
import math

import numpy as np
import pytest
import yaml

from scenebot.capturelog import photo_records, read_log
from tests.fixtures.workflow import PERSON_WALK, snakemake, why

pytestmark = pytest.mark.slow  # two rounds of a small person's campaign (~5 min)

K = 3
CONFIG = dict(PERSON_WALK, max_rounds=2, score={"n_candidates": 100}, goals={"k": K})
TARGETS = [
    "results/office/round_001/fulfilment.json",
    "results/office/round_001/evaluation.json",
    "results/office/round_001/guide/index.html",
]


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    workdir = tmp_path_factory.mktemp("person_sim")
    (workdir / "config.yaml").write_text(yaml.safe_dump(CONFIG))
    res = snakemake(workdir, *TARGETS)
    assert res.returncode == 0, why(res, workdir)
    return workdir / "results" / "office"


def test_round_zero_is_the_walk_with_its_truth_and_a_metric_map(campaign):
    log = campaign / "round_000" / "capture" / "log.jsonl"
    photos = photo_records(log)
    assert len(photos) == 32 and all("truth" in p for p in photos)
    (session,) = [r for r in read_log(log) if r.get("type") == "session"]
    eye = session["eye_height_m"]  # the person's own, drawn once per campaign
    assert 1.2 <= eye <= 1.8
    heights = np.array([p["truth"]["center"][2] for p in photos])
    assert np.all(np.abs(heights - eye) < 4 * 0.05)  # person_sim.height_std_m
    (tape,) = [r for r in read_log(log) if r.get("event") == "known_distance"]
    a, b = (np.array(p["truth"]["center"]) for p in photos if p["image"] in
            (tape["image_a"], tape["image_b"]))  # fmt: skip
    assert tape["distance_m"] == pytest.approx(np.linalg.norm(a - b), abs=0.05)
    report = json.loads((campaign / "round_000" / "sfm" / "report.json").read_text())
    assert report["scale"]["source"] == "known_distance"
    acc = report["accuracy"]
    assert abs(acc["metric_scale_error"]) < 0.05  # metres, from the person's tape
    assert acc["position_error_m"]["median"] < 0.1


def test_round_one_takes_the_guides_shots_from_the_inbox(campaign):
    cap = campaign / "round_001" / "capture"
    goals = json.loads((campaign / "round_000" / "goals.json").read_text())["goals"]
    shots = list(read_log(cap / "inbox" / "person-sim.jsonl"))
    assert {s["aimed_shot"] for s in shots} == {g["rank"] for g in goals}
    taken = [s for s in shots if "image" in s]
    assert taken, shots
    photos = photo_records(cap / "log.jsonl")
    assert len(photos) == len(taken)
    for s, p in zip(taken, photos, strict=True):
        inbox_photo = cap / "inbox" / s["image"]
        assert p["source"] == f"inbox/{s['image']}"
        data = (cap / p["image"]).read_bytes()
        assert data == inbox_photo.read_bytes()  # copied, the inbox photo left as it was
        assert p["sha256"] == hashlib.sha256(data).hexdigest()
        assert p["aimed_shot"] == s["aimed_shot"] and p["truth"] == s["truth"]
        # the person's error against its settings (0.2 m per axis, 10 deg): 5 sigma
        tc, aim = np.array(p["truth"]["center"]), np.array(s["aimed"]["center"])
        assert np.linalg.norm((tc - aim)[:2]) < 5 * 0.2 * math.sqrt(2)
        R = np.array(p["truth"]["R_cam_from_world"])
        heading = math.atan2(R[2][1], R[2][0])
        assert abs(math.degrees(math.remainder(heading - s["aimed"]["heading"], 2 * math.pi))) < 50
    for s in shots:
        if "skipped" in s:
            assert "m is" in s["skipped"]  # where, and why


def test_the_shots_fulfilled_and_how_far_the_person_truly_was(campaign):
    doc = json.loads((campaign / "round_001" / "fulfilment.json").read_text())
    photos = photo_records(campaign / "round_001" / "capture" / "log.jsonl")
    assert doc["summary"]["photos"] == len(photos) == len(doc["photos"])
    assert doc["summary"]["shots"] == K
    for row in doc["photos"]:
        assert row["registered"] == (row["nearest_shot"] is not None)
        if row["registered"] and not row["fulfils"]:
            assert "fulfils no shot" in row["message"]
        if row["fulfils"]:
            assert row["nearest_shot"]["distance"] <= 0.3
    for shot in doc["shots"]:
        for name in shot["fulfilled_by"]:
            assert shot["rank"] in next(p for p in doc["photos"] if p["image"] == name)["fulfils"]
    ev = json.loads((campaign / "round_001" / "evaluation.json").read_text())
    ps = ev["person_shots"]
    assert ps["fulfilment"]["shots"] == K
    assert ps["fulfilment"]["fulfilled"] == doc["summary"]["fulfilled"]
    registered = [r for r in doc["photos"] if r["registered"]]
    assert len(ps["shots"]) == len(photos)
    for row in ps["shots"]:
        # the shot as the evaluation places it in the world vs where the person truly stood:
        # its walking error (person_error_m) plus how it read the guide's map (a few cm)
        assert row["true_distance_m"] < row["person_error_m"] + 0.15
    # the map the shots were fulfilled in is metric and true: a photo within 0.3 m of the
    # shot it aimed at in the map stands within 0.3 m plus the maps' errors of it in the world
    by_image = {r["image"]: r for r in ps["shots"]}
    for r in registered:
        true = by_image[r["image"].split("/capture/", 1)[1]]
        if true["shot"] in r["fulfils"]:
            assert true["true_distance_m"] < 0.3 + 0.15
    assert ev["sfm"]["position_error_m"]["median"] < 0.1
