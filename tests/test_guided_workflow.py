"""A person's guided campaign (``robot: guided``) through the workflow, on the canned photos:
round 0 is 40 of them as the person's folder; the next run stops at the empty inbox saying
where to put photos; with the other 5 (and a broken file) in round 1's inbox, round 1 takes
them in, maps them and says which shots they fulfilled, naming those that fulfil none."""

from __future__ import annotations

import json
import shutil

import pytest
import yaml

from scenebot.capturelog import photo_records, read_log
from tests.fixtures.workflow import CANNED, photo_folder, snakemake, why

pytestmark = [
    pytest.mark.slow,  # two maps of 40 and 45 small photos, their decisions (~4 min)
    pytest.mark.skipif(not (CANNED / "log.jsonl").exists(), reason="canned photo set missing"),
]

HELD_BACK = 5


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    workdir = tmp_path_factory.mktemp("guided")
    folder, _, cfg = photo_folder(workdir / "my photos")
    held = sorted(folder.iterdir())[-HELD_BACK:]
    later = workdir / "later"
    later.mkdir()
    for p in held:
        shutil.move(p, later / p.name)
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    cfg = dict(cfg, robot="guided", max_rounds=2, score={"n_candidates": 100}, goals={"k": 3})
    cfg["sfm"] = dict(cfg["sfm"], num_threads=1)
    (workdir / "config.yaml").write_text(yaml.safe_dump(cfg))
    first = snakemake(workdir, "results/office/round_000/guide/index.html")
    assert first.returncode == 0, why(first, workdir)
    empty = snakemake(workdir, "results/office/round_001/fulfilment.json")
    scene = workdir / "results" / "office"
    inbox = scene / "round_001" / "capture" / "inbox"
    inbox.mkdir(parents=True, exist_ok=True)
    for p in sorted(later.iterdir()):
        shutil.copy(p, inbox / p.name)
    (inbox / "broken.jpg").write_bytes(b"\xff\xd8 not a photo")
    (inbox / "notes.txt").write_text("the kitchen next")
    in_inbox = {p.name: p.read_bytes() for p in inbox.iterdir()}
    second = snakemake(
        workdir, "results/office/round_001/fulfilment.json", "results/office/round_001/goals.json"
    )
    assert second.returncode == 0, why(second, workdir)
    return scene, folder, before, in_inbox, empty, second


def test_an_empty_inbox_stops_saying_where_to_put_the_photos(campaign):
    *_, empty, _ = campaign
    assert empty.returncode != 0
    text = empty.stderr
    assert "results/office/round_001/capture/inbox/" in text
    assert "round_000/guide/index.html" in text and "max_rounds=1" in text


def test_round_one_takes_in_the_inbox_and_leaves_it_and_the_folder_alone(campaign):
    scene, folder, before, in_inbox, _, _ = campaign
    cap = scene / "round_001" / "capture"
    photos = photo_records(cap / "log.jsonl")
    taken = [f"inbox/{n}" for n in sorted(in_inbox) if n.endswith(".jpg") and n != "broken.jpg"]
    assert [p["source"] for p in photos] == taken
    (left,) = [e for e in read_log(cap / "log.jsonl") if e.get("event") == "photo_left_out"]
    assert left["source"] == "inbox/broken.jpg" and "not an image" in left["reason"]
    inbox = cap / "inbox"
    assert {p.name: p.read_bytes() for p in inbox.iterdir()} == in_inbox
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before
    r0 = photo_records(scene / "round_000" / "capture" / "log.jsonl")
    assert len(r0) == len(before) and all(p["image"].startswith("images/r000_") for p in r0)


def test_round_one_says_which_shots_each_photo_fulfilled(campaign):
    scene, *_ = campaign
    doc = json.loads((scene / "round_001" / "fulfilment.json").read_text())
    report = json.loads((scene / "round_001" / "sfm" / "report.json").read_text())
    assert report["photos"] == 40 + HELD_BACK
    assert doc["summary"]["photos"] == HELD_BACK and doc["summary"]["shots"] == 3
    for row in doc["photos"]:
        name = row["source"].split("/", 1)[1]
        if not row["registered"]:
            assert (
                f"{name} ({row['image'].split('/capture/', 1)[1]}) did not register"
                in (row["message"])
            )
        elif not row["fulfils"]:
            assert f"{name} (" in row["message"] and "fulfils no shot" in row["message"]
            assert "It is kept" in row["message"]
    goals = json.loads((scene / "round_001" / "goals.json").read_text())
    assert "score_gain" in goals and goals["map_images"] == report["registered"]
