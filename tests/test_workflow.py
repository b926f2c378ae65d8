"""The Snakemake workflow end to end: runs, re-runs nothing, re-runs exactly what changed."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
SNAKEMAKE = [sys.executable, "-m", "snakemake"]

SMALL = {
    "scene": "office",
    "sim": {"camera": {"width": 160, "height": 120}},
    "exploration": {"photos": 12},
}


def snakemake(workdir: Path, *args: str) -> subprocess.CompletedProcess:
    cmd = [*SNAKEMAKE, "-s", str(ROOT / "Snakefile"), "-d", str(workdir), "--cores", "2", *args]
    return subprocess.run(cmd, capture_output=True, text=True, cwd=workdir, timeout=900)


@pytest.fixture
def workdir(tmp_path):
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(SMALL))
    return tmp_path


@pytest.mark.slow
def test_workflow_runs_then_has_nothing_to_do_then_reruns_what_changed(workdir):
    first = snakemake(workdir)
    assert first.returncode == 0, first.stderr[-3000:]
    capture = workdir / "results/office/round_000/capture"
    assert len(list((capture / "images").glob("*.jpg"))) == 12
    assert (capture / "trajectory.png").is_file()
    assert (workdir / "results/office/benchmarks/capture_round0.tsv").is_file()

    again = snakemake(workdir, "-n")
    assert again.returncode == 0
    assert "Nothing to be done" in again.stdout + again.stderr

    cfg = dict(SMALL, sim={"camera": {"width": 160, "height": 120}, "slip": {"turn": 0.05}})
    (workdir / "config.yaml").write_text(yaml.safe_dump(cfg))
    changed = snakemake(workdir, "-n")
    assert changed.returncode == 0
    out = changed.stdout + changed.stderr
    assert "capture_round0" in out and "Params have changed" in out

    rerun = snakemake(workdir)
    assert rerun.returncode == 0, rerun.stderr[-3000:]
    superseded = list((capture / "superseded").glob("*/images/*.jpg"))
    assert len(superseded) == 12  # the first photos were kept


@pytest.mark.slow
def test_an_invalid_config_value_stops_the_workflow_naming_the_key(workdir):
    bad = dict(SMALL, robot="roomba")
    (workdir / "config.yaml").write_text(yaml.safe_dump(bad))
    res = snakemake(workdir, "-n")
    assert res.returncode != 0
    assert "robot: got 'roomba'; allowed values: 'sim'" in res.stdout + res.stderr


def test_workflow_lint_and_format_are_clean():
    if shutil.which("snakefmt") is None and not (Path(sys.executable).parent / "snakefmt").exists():
        pytest.skip("snakefmt not installed")
    fmt = subprocess.run(
        [str(Path(sys.executable).parent / "snakefmt"), "--check", "Snakefile", "rules/"],
        cwd=ROOT, capture_output=True, text=True,
    )  # fmt: skip
    assert fmt.returncode == 0, fmt.stderr
