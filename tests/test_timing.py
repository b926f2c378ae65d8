"""timing.json and timing.png: where a campaign's time went, from Snakemake's benchmark files."""

from __future__ import annotations

import json

import pytest

from scenebot import cli, timing

HEAD = "s\th:m:s\tmax_rss\tmax_vms\tmax_uss\tmax_pss\tio_in\tio_out\tmean_load\tcpu_time\n"


def bench(path, *rows):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(HEAD + "".join(f"{s}\t0:00:01\t{rss}\t1\t1\t1\t0\t0\t50\t{cpu}\n"
                                   for s, cpu, rss in rows))  # fmt: skip


@pytest.fixture
def campaign(tmp_path):
    b = tmp_path / "benchmarks"
    bench(b / "capture_round0.tsv", (30.0, 10.0, 300))
    bench(b / "round_000" / "sfm.tsv", (100.0, 190.0, 400))
    bench(b / "round_001" / "capture.tsv", (60.0, 20.0, 500))
    bench(b / "round_001" / "sfm.tsv", (40.0, 70.0, 380))
    bench(b / "dense.tsv", (200.0, 390.0, 900), (100.0, 190.0, 800))  # two repeats: the mean
    return b


def test_stages_sum_their_rounds_and_say_how_many_cores_they_kept_busy(campaign, tmp_path):
    doc = timing.write(campaign, tmp_path / "timing.json", tmp_path / "timing.png")
    st = doc["stages"]
    assert st["capture"] == pytest.approx(
        {"jobs": 2, "seconds": 90.0, "cpu_seconds": 30.0, "max_rss_mb": 500.0,
         "cpu_per_wall": 0.33})  # fmt: skip
    assert st["sfm"]["seconds"] == 140.0 and st["sfm"]["cpu_per_wall"] == pytest.approx(1.86)
    assert st["dense"]["seconds"] == 150.0 and st["dense"]["max_rss_mb"] == 850.0
    rounds = {(j["stage"], j["round"]) for j in doc["jobs"]}
    assert {("capture", 0), ("sfm", 0), ("capture", 1), ("sfm", 1), ("dense", None)} == rounds
    assert doc["jobs_seconds"] == pytest.approx(380.0)
    assert json.loads((tmp_path / "timing.json").read_text())["stages"] == st
    assert (tmp_path / "timing.png").stat().st_size > 10_000


def test_no_benchmarks_is_an_error_naming_the_folder(tmp_path, capsys):
    out = tmp_path / "t.json"
    code = cli.main(["timing", "--benchmarks", str(tmp_path / "none"), "--out", str(out)])
    assert code == 1 and "none: no benchmark files" in capsys.readouterr().err
    assert not out.exists()
