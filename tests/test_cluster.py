"""The workflow on a SLURM cluster (profiles/slurm, Snakemake's SLURM executor plugin): a real
one-node cluster on this machine (scripts/slurm-local: munged, slurmctld, slurmd from Debian's
packages), the canned photos through every stage, one job cancelled on the way."""

from __future__ import annotations

import importlib.util
import json
import os
import re
import shutil
import subprocess
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest
import yaml
import yte

from tests.fixtures.workflow import (
    CANNED,
    ROOT,
    SNAKEMAKE,
    photo_campaign_config,
    shared_photo_campaign,
    why,
)

SCRIPT = ROOT / "scripts" / "slurm-local"
PROFILE = ROOT / "profiles" / "slurm"
SLURM_BINARIES = ("munged", "mungekey", "slurmctld", "slurmd", "sbatch", "squeue", "scancel")
# the rules of a `robot: photos` campaign that run as SLURM jobs, and those that run here
CLUSTER_RULES = {
    "sfm", "mesh", "score", "goals", "goals_preview", "guide", "campaign", "dense", "proxy",
    "tour",
}  # fmt: skip
LOCAL_RULES = {"timing", "all"}


def workflow_rules() -> dict[str, str]:
    """Every rule of rules/*.smk: name -> its text."""
    text = "\n".join(p.read_text() for p in sorted((ROOT / "rules").glob("*.smk")))
    parts = re.split(r"^(?:rule|checkpoint) (\w+):$", text, flags=re.M)
    return dict(zip(parts[1::2], parts[2::2], strict=True))


def profile() -> dict:
    """profiles/slurm/config.yaml as Snakemake reads it (yte, in this environment)."""
    with (PROFILE / "config.yaml").open() as f:
        return yte.process_yaml(f, require_use_yte=True)


def test_the_profile_sizes_every_stage_the_cluster_runs_and_keeps_the_robot_here(monkeypatch):
    """Every rule with a benchmark that is not local gets memory and time from the profile,
    every rule that takes all cores gets threads; the captures are local; a GPU only when
    asked for, for dense and score."""
    rules = workflow_rules()
    local = {name for name, text in rules.items() if "localrule: True" in text}
    assert {"capture_round0", "capture_adaptive"} <= local
    monkeypatch.delenv("SCENEBOT_SLURM_GPU_PARTITION", raising=False)
    cpu = profile()
    assert cpu["executor"] == "slurm" and cpu["slurm-status-command"] == "squeue"
    measured = {name for name, text in rules.items() if "benchmark:" in text} - local
    sized = cpu["set-resources"]
    assert measured <= set(sized) <= set(rules) - local
    assert all({"mem_mb", "runtime"} <= set(sized[name]) for name in sized)
    threaded = {name for name, text in rules.items() if "threads: ALL_CORES" in text}
    assert set(cpu["set-threads"]) == threaded
    assert not any("gpu" in r for r in sized.values())
    monkeypatch.setenv("SCENEBOT_SLURM_GPU_PARTITION", "gpu")
    gpu = profile()["set-resources"]
    assert {name for name, r in gpu.items() if r.get("gpu")} == {"dense", "score"}
    assert gpu["dense"]["slurm_partition"] == "gpu"


def _why_not() -> str | None:
    """Why this machine cannot run the one-node cluster, or None."""
    missing = [b for b in SLURM_BINARIES if shutil.which(b) is None]
    if missing:
        return f"SLURM not installed ({', '.join(missing)}: make system-test installs it)"
    if os.geteuid() != 0:
        return "the one-node SLURM cluster needs root (slurmd)"
    if importlib.util.find_spec("snakemake_executor_plugin_slurm") is None:
        return "snakemake-executor-plugin-slurm not installed (pip install -e '.[cluster]')"
    return None


@pytest.fixture(scope="session")
def slurm_cluster(tmp_path_factory):
    """A one-node SLURM cluster for the session, stopped afterwards."""
    reason = _why_not()
    if reason:
        pytest.skip(reason)
    env = dict(os.environ, SLURM_LOCAL_DIR=str(tmp_path_factory.mktemp("slurm")))
    env.pop("SLURM_CONF", None)
    start = subprocess.run([str(SCRIPT), "start"], env=env, capture_output=True, text=True,
                           timeout=180, check=False)  # fmt: skip
    if start.returncode != 0:
        subprocess.run([str(SCRIPT), "stop"], env=env, capture_output=True, timeout=60)
        pytest.fail(f"scripts/slurm-local start failed:\n{start.stdout}{start.stderr}")
    yield env
    subprocess.run([str(SCRIPT), "stop"], env=env, capture_output=True, timeout=60)


def cluster_snakemake(workdir: Path, env: dict, *args: str) -> subprocess.CompletedProcess:
    """snakemake with the SLURM profile, as a user runs it (no --cores)."""
    cmd = [*SNAKEMAKE, "-s", str(ROOT / "Snakefile"), "-d", str(workdir),
           "--profile", str(PROFILE), *args]  # fmt: skip
    return subprocess.run(cmd, capture_output=True, text=True, cwd=workdir, env=env,
                          timeout=1500, check=False)  # fmt: skip


def jobs_of(output: str) -> dict[int, dict]:
    """Snakemake's jobs in its output: jobid -> rule, whether it ran here (``localrule``) and
    the SLURM job ids it was submitted as (several when it was retried)."""
    jobs: dict[int, dict] = {}
    current = None
    for line in output.splitlines():
        head = re.match(r"(local)?(?:rule|checkpoint) (\w+):$", line)
        if head:
            current = {"rule": head.group(2), "local": bool(head.group(1)), "slurm": []}
            continue
        jobid = re.match(r"\s+jobid: (\d+)$", line)
        if jobid and current is not None:
            jobs.setdefault(int(jobid.group(1)), current)
            current = None
        sub = re.match(r"Job (\d+) has been submitted with SLURM jobid (\d+) \(log: (.+)\)\.", line)
        if sub:
            jobs[int(sub.group(1))]["slurm"].append((sub.group(2), Path(sub.group(3))))
    return jobs


def error_block(output: str, rule: str) -> str:
    """Snakemake's report of ``rule``'s failed job: its ``Error in rule`` line and the
    indented lines after it (message, input, output, log, shell)."""
    lines = output.splitlines()
    start = lines.index(f"Error in rule {rule}:")
    block = [lines[start]]
    for line in lines[start + 1 :]:
        if not line.startswith((" ", "\t")):
            break
        block.append(line)
    return "\n".join(block)


def without_times(doc):
    """A JSON document without its run times (``seconds``, ``timings_s``)."""
    if isinstance(doc, dict):
        return {k: without_times(v) for k, v in doc.items() if k not in ("seconds", "timings_s")}
    return [without_times(v) for v in doc] if isinstance(doc, list) else doc


def cancel_when_running(rule: str, log: Path, env: dict, done: threading.Event) -> list[str]:
    """Watch the queue from a thread; once ``rule``'s job runs and its stage has begun
    writing ``log``, `scancel` it. Returns the list the cancelled job id is put in."""
    cancelled: list[str] = []

    def watch():
        while not done.is_set():
            queue = subprocess.run(["squeue", "-h", "-t", "R", "-o", "%i|%k"], env=env,
                                   capture_output=True, text=True, check=False).stdout  # fmt: skip
            rows = (line.split("|") for line in queue.split())
            ids = [i for i, comment in rows if comment == f"rule_{rule}"]
            if ids and log.is_file() and log.stat().st_size > 0:
                time.sleep(2)  # well into the stage
                subprocess.run(["scancel", ids[0]], env=env, check=True)
                cancelled.append(ids[0])
                return
            time.sleep(0.5)

    threading.Thread(target=watch, daemon=True).start()
    return cancelled


@pytest.mark.slow
@pytest.mark.cluster
@pytest.mark.skipif(not (CANNED / "log.jsonl").exists(), reason="canned photo set missing")
def test_every_stage_runs_as_a_slurm_job_and_decides_as_a_local_run(
    slurm_cluster, tmp_path, tmp_path_factory
):
    """The canned photos (`robot: photos`, the smallest every-stage campaign of
    test_workflow_photos.py) through every stage on the cluster: each stage is a SLURM job,
    the bookkeeping stays here, a dense job cancelled mid-run is reported with the rule's log
    and retried, the photos are untouched, and the decisions equal a local run's (that
    campaign, tests/fixtures/workflow.py's ``shared_photo_campaign``: run beside, or by the
    test of test_workflow_photos.py that asked first). SfM maps on one thread (multi-threaded
    mapping is not repeatable; dense and the tour are not compared)."""
    workdir = tmp_path / "cluster"
    workdir.mkdir()
    folder, before, cfg = photo_campaign_config(workdir / "photos")
    (workdir / "config.yaml").write_text(yaml.safe_dump(cfg))

    done = threading.Event()
    cancelled = cancel_when_running("dense", workdir / "results/office/logs/dense.log",
                                    slurm_cluster, done)  # fmt: skip
    with ThreadPoolExecutor(1) as pool:  # the local run beside (or read, if run already)
        local_run = pool.submit(shared_photo_campaign, tmp_path_factory)
        try:
            res = cluster_snakemake(workdir, slurm_cluster)
        finally:
            done.set()
        local = local_run.result()
    local_dir = local.workdir
    assert local.round0.returncode == 0, why(local.round0, local_dir)
    assert local.final.returncode == 0, why(local.final, local_dir)
    out = res.stdout + res.stderr
    assert res.returncode == 0, why(res, workdir)

    jobs = list(jobs_of(out).values())
    assert {j["rule"] for j in jobs if not j["local"]} == CLUSTER_RULES
    assert {j["rule"] for j in jobs if j["local"]} == LOCAL_RULES
    for job in jobs:
        if job["local"]:
            assert not job["slurm"], job
            continue
        assert job["slurm"], f"rule {job['rule']} ran without a SLURM job id"
        _, slurm_log = job["slurm"][-1]
        assert slurm_log.is_file()
        text = slurm_log.read_text()  # a checkpoint (the guide page) says so instead of "rule"
        assert f"rule {job['rule']}:" in text or f"checkpoint {job['rule']}:" in text

    # the cancelled job: reported with the rule's log, then retried to completion
    assert cancelled, "the dense job was never seen running"
    dense = next(j for j in jobs if j["rule"] == "dense")
    assert [i for i, _ in dense["slurm"]] == [cancelled[0], dense["slurm"][1][0]]
    report = error_block(out, "dense")
    assert f"SLURM-job '{cancelled[0]}' failed, SLURM status is: 'CANCELLED'" in report
    assert re.search(r"^\s+log: results/office/logs/dense\.log, ", report, re.M), report
    assert (workdir / "results/office/final/dense/fused.ply").stat().st_size > 1000
    assert (workdir / "results/office/final/tour/index.html").is_file()
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before  # photos untouched

    # the decisions equal the local run's: the campaign summary, the map (its report but
    # the times), the free space, every candidate's score, the goals
    results, local_results = workdir / "results/office", local_dir / "results/office"
    for name in ("round_000/freespace.json", "round_000/candidates.csv"):
        assert (results / name).read_bytes() == (local_results / name).read_bytes(), name
    for name in ("round_000/sfm/report.json", "round_000/goals.json", "campaign.json"):
        mine, theirs = (json.loads((d / name).read_text()) for d in (results, local_results))
        assert without_times(mine) == without_times(theirs), name
