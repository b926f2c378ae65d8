"""A person's folder of photos (robot: photos) through the workflow."""

from __future__ import annotations

import json

import pytest
import yaml

from tests.fixtures.workflow import CANNED, photo_folder, small_final_stages, snakemake, why


@pytest.mark.slow
@pytest.mark.skipif(not (CANNED / "log.jsonl").exists(), reason="canned photo set missing")
def test_bring_your_own_photos_make_round_0(workdir):
    """robot: photos: a plain folder of JPEGs (no log, no robot) becomes round 0's map."""
    folder, before, cfg = photo_folder(workdir / "my_photos")
    (workdir / "config.yaml").write_text(yaml.safe_dump(cfg))
    res = snakemake(workdir, "results/office/round_000/sfm/map.png")
    assert res.returncode == 0, why(res, workdir)
    report = json.loads((workdir / "results/office/round_000/sfm/report.json").read_text())
    assert report["registered"] >= 0.8 * report["photos"]
    assert not (workdir / "results/office/round_000/capture").exists()  # no robot ran
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before  # photos untouched


@pytest.mark.slow
@pytest.mark.skipif(not (CANNED / "log.jsonl").exists(), reason="canned photo set missing")
def test_bring_your_own_photos_build_the_final_targets(workdir):
    """robot: photos through `rule all`: every stage after sfm receives only its own config
    sections and must still accept them (the photo folder is the sfm stage's business), up to
    the dense model and the tour. Small settings keep it cheap."""
    folder, before, cfg = photo_folder(workdir / "my photos")  # a space, as users have
    cfg = small_final_stages(cfg)
    (workdir / "config.yaml").write_text(yaml.safe_dump(cfg))
    res = snakemake(workdir)
    assert res.returncode == 0, why(res, workdir)
    results = workdir / "results/office"
    assert (results / "final/dense/fused.ply").stat().st_size > 1000
    assert (results / "final/tour/index.html").is_file()
    campaign = json.loads((results / "campaign.json").read_text())
    assert [r["round"] for r in campaign["rounds"]] == [0]  # a folder is one round
    assert not (results / "round_000/capture").exists()  # no robot ran
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before  # photos untouched
    assert snakemake(workdir, "-n").stdout.count("Nothing to be done") == 1
