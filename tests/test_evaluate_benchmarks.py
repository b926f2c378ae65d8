"""benchmarks/run.py: protocol discovery, rows and ratios, campaign TSVs, the written table."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def runner():
    spec = importlib.util.spec_from_file_location("bench_run", ROOT / "benchmarks" / "run.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


def test_a_module_with_the_protocol_function_joins_by_itself(tmp_path, runner):
    (tmp_path / "bench_fake.py").write_text(
        "def bench(quick):\n"
        "    return [{'group': 'fake', 'name': 'thing', 'median': 2.0, 'unit': 'ms',\n"
        "             'repeats': 3 if quick else 5, 'reference': 'slow thing',\n"
        "             'reference_median': 10.0}]\n"
    )
    (tmp_path / "bench_noproto.py").write_text("X = 1\n")
    groups = runner.discover(True, "cpu", False, None, folder=tmp_path)
    assert "fake" in groups and "noproto" not in groups
    assert list(groups)[: len(runner.GROUP_ORDER)] == runner.GROUP_ORDER
    rows = [runner._row(r, "fake") for r in groups["fake"]()]
    assert rows[0].repeats == 3 and rows[0].ratio == pytest.approx(5.0)
    only = runner.discover(True, "cpu", False, {"fake"}, folder=tmp_path)
    assert list(only) == ["fake"]


def test_campaign_rows_come_from_snakemake_benchmark_files(tmp_path, runner):
    tsv = tmp_path / "office" / "benchmarks" / "round_000" / "sfm.tsv"
    tsv.parent.mkdir(parents=True)
    head = "s\th:m:s\tmax_rss\tmax_vms\tmax_uss\tmax_pss\tio_in\tio_out\tmean_load\tcpu_time\n"
    tsv.write_text(head + "98.0\t0:01:38\t300.4\t1\t1\t1\t1\t1\t1\t121.6\n")
    (tmp_path / "office" / "benchmarks" / "dense.tsv").write_text(
        head + "140.0\t0:02:20\t900\t1\t1\t1\t1\t1\t1\t210\n"
        "150.0\t0:02:30\t960\t1\t1\t1\t1\t1\t1\t220\n"
    )
    rows = runner.bench_campaign(True, results=tmp_path)
    by = {r.name: r for r in rows}
    # one row per stage, summed over its jobs; a file with repeats counts their mean
    assert by["office: sfm (1 jobs)"].median == pytest.approx(98.0)
    assert by["office: sfm (1 jobs)"].cpu_wall == pytest.approx(121.6 / 98.0, abs=0.01)
    assert "max RSS 300 MB" in by["office: sfm (1 jobs)"].note
    assert by["office: dense (1 jobs)"].median == pytest.approx(145.0)
    assert by["office: all jobs"].median == pytest.approx(243.0)
    assert "CPU 337 s" in by["office: all jobs"].note
    assert all(r.ratio is None for r in rows)


def test_the_table_is_written_as_markdown_and_json(tmp_path, runner):
    out = tmp_path / "results.md"
    rc = runner.main(["--quick", "--only", "machine", "--out", str(out)])
    assert rc == 0
    md = out.read_text()
    assert "| machine | numpy 1024x1024 float64 matmul |" in md
    assert "cores" in md and "numpy" in md  # the machine is described
    data = json.loads(out.with_suffix(".json").read_text())
    assert data["machine"]["cores"] >= 1 and data["failures"] == {}
    assert {r["group"] for r in data["rows"]} == {"machine"}
    assert all(r["median"] > 0 for r in data["rows"])


def test_a_failing_benchmark_is_reported_and_the_rest_still_runs(tmp_path, runner, monkeypatch):
    (tmp_path / "bench_broken.py").write_text("def bench(quick):\n    raise RuntimeError('x')\n")
    real = runner.discover
    monkeypatch.setattr(runner, "discover", lambda q, a, f, o: real(q, a, f, o, folder=tmp_path))
    out = tmp_path / "r.md"
    rc = runner.main(["--quick", "--only", "broken,machine", "--out", str(out)])
    assert rc == 1
    data = json.loads(out.with_suffix(".json").read_text())
    assert "broken" in data["failures"] and any(r["group"] == "machine" for r in data["rows"])
    assert "FAILED" in out.read_text()


def test_exported_dense_views_read_back_as_the_same_pixels_and_workspace(tmp_path):
    """`bench_dense.py --export` writes what `--views` and `--colmap` read on a GPU machine."""
    spec = importlib.util.spec_from_file_location(
        "bench_dense", ROOT / "benchmarks" / "bench_dense.py"
    )
    bd = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bd)
    views, truth = bd.export_views(tmp_path / "x", 96, 72, 3)
    back, back_truth = bd.load_views(tmp_path / "x" / "views.npz")
    assert (
        [v.name for v in back]
        == [v.name for v in views]
        == ["view_000.jpg", "view_001.jpg", "view_002.jpg"]
    )
    for a, b, da, db in zip(views, back, truth, back_truth, strict=True):
        assert np.abs(a.gray - b.gray).max() <= 0.5 / 255 + 1e-6
        assert np.allclose(a.K, b.K) and np.allclose(a.R, b.R) and np.allclose(a.t, b.t)
        assert np.array_equal(da, db) and (db > 0).mean() > 0.9
    # the middle camera sits between the others; every view has the other two as sources
    assert np.linalg.norm(back[0].t - back[2].t) > np.linalg.norm(back[0].t - back[1].t)
    cfg = (tmp_path / "x" / "dense" / "stereo" / "patch-match.cfg").read_text().split("\n")
    assert cfg[0] == "view_000.jpg" and cfg[1] == "view_001.jpg, view_002.jpg"
    assert len(list((tmp_path / "x" / "dense" / "images").iterdir())) == 3
