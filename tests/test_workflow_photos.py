"""A person's folder of photos (robot: photos) through the workflow.

Both tests check one campaign (tests/fixtures/workflow.py, ``shared_photo_campaign``): round
0's map built by its own target, then `rule all` going on from it (the same config: the stages
after the map read only their own sections). tests/test_cluster.py compares its SLURM run with
the same campaign: it is run once per test session."""

from __future__ import annotations

import json

import pytest

from tests.fixtures.workflow import CANNED, shared_photo_campaign, snakemake, why

pytestmark = pytest.mark.skipif(
    not (CANNED / "log.jsonl").exists(), reason="canned photo set missing"
)


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    return shared_photo_campaign(tmp_path_factory)


@pytest.mark.slow
def test_bring_your_own_photos_make_round_0(campaign):
    """robot: photos: a plain folder of JPEGs (no log, no robot) becomes round 0's map."""
    workdir, folder = campaign.workdir, campaign.folder
    assert campaign.round0.returncode == 0, why(campaign.round0, workdir)
    report = json.loads((workdir / "results/office/round_000/sfm/report.json").read_text())
    assert report["registered"] >= 0.8 * report["photos"]
    assert not (workdir / "results/office/round_000/capture").exists()  # no robot ran
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == campaign.before  # untouched


@pytest.mark.slow
def test_bring_your_own_photos_build_the_final_targets(campaign):
    """robot: photos through `rule all` (going on from round 0's map): every stage after sfm
    receives only its own config sections and must still accept them (the photo folder is the
    sfm stage's business), up to the dense model and the tour. Small settings keep it cheap."""
    workdir, folder = campaign.workdir, campaign.folder
    assert campaign.round0.returncode == 0, why(campaign.round0, workdir)
    assert campaign.final.returncode == 0, why(campaign.final, workdir)
    results = workdir / "results/office"
    assert (results / "final/dense/fused.ply").stat().st_size > 1000
    assert (results / "final/tour/index.html").is_file()
    campaign_json = json.loads((results / "campaign.json").read_text())
    assert [r["round"] for r in campaign_json["rounds"]] == [0]  # a folder is one round
    assert not (results / "round_000/capture").exists()  # no robot ran
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == campaign.before  # untouched
    assert snakemake(workdir, "-n").stdout.count("Nothing to be done") == 1
