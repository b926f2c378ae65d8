"""Where a campaign's time went: ``results/{scene}/timing.json`` and ``timing.png``.

Read from the benchmark files Snakemake writes for every job (``results/{scene}/benchmarks/``,
one ``.tsv`` per rule and round: wall time ``s``, ``cpu_time``, ``max_rss`` in MB): per job,
per stage (summed over the rounds) and in all. CPU time / wall time says how many cores a stage
kept busy. A job run again replaces its file, so the figures are those of the last run of
each job.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

from scenebot.pictures import pyplot

STAGE_OF = {"capture_round0": "capture"}
"""Benchmark files named otherwise than their stage."""


def read_benchmarks(bench_dir: Path) -> list[dict]:
    """One record per benchmark file: ``stage``, ``round`` (None outside the rounds), wall
    ``seconds``, ``cpu_seconds``, ``max_rss_mb``; a file with several repeats gives their
    mean."""
    jobs = []
    for tsv in sorted(Path(bench_dir).glob("**/*.tsv")):
        with tsv.open(encoding="utf-8") as f:
            rows = list(csv.DictReader(f, delimiter="\t"))
        if not rows:
            continue
        rel = tsv.relative_to(bench_dir)
        round_ = int(rel.parts[0][6:]) if rel.parts[0].startswith("round_") else None
        if tsv.stem == "capture_round0":
            round_ = 0

        def mean(key: str, rows=rows) -> float | None:
            vals = [float(r[key]) for r in rows if r.get(key) not in (None, "", "NA", "-")]
            return sum(vals) / len(vals) if vals else None

        jobs.append({
            "stage": STAGE_OF.get(tsv.stem, tsv.stem), "round": round_, "file": rel.as_posix(),
            "seconds": mean("s"), "cpu_seconds": mean("cpu_time"), "max_rss_mb": mean("max_rss"),
        })  # fmt: skip
    return jobs


def by_stage(jobs: list[dict]) -> dict[str, dict]:
    """Wall and CPU seconds per stage (summed over its jobs), its jobs, its peak memory, and
    CPU / wall; the stages in the order of their first job's file."""
    out: dict[str, dict] = {}
    for j in jobs:
        s = out.setdefault(j["stage"], {"jobs": 0, "seconds": 0.0, "cpu_seconds": 0.0,
                                        "max_rss_mb": 0.0})  # fmt: skip
        s["jobs"] += 1
        s["seconds"] += j["seconds"] or 0.0
        s["cpu_seconds"] += j["cpu_seconds"] or 0.0
        s["max_rss_mb"] = max(s["max_rss_mb"], j["max_rss_mb"] or 0.0)
    for s in out.values():
        s["cpu_per_wall"] = round(s["cpu_seconds"] / s["seconds"], 2) if s["seconds"] else None
        for k in ("seconds", "cpu_seconds", "max_rss_mb"):
            s[k] = round(s[k], 1)
    return out


def write(bench_dir: Path, out_json: Path, out_png: Path | None = None) -> dict:
    """``timing.json`` (and the picture) of the campaign whose benchmark folder is given."""
    jobs = read_benchmarks(bench_dir)
    if not jobs:
        raise FileNotFoundError(f"{bench_dir}: no benchmark files; run the campaign first")
    stages = by_stage(jobs)
    wall = sum(s["seconds"] for s in stages.values())
    cpu = sum(s["cpu_seconds"] for s in stages.values())
    doc = {
        "benchmarks": str(bench_dir),
        "jobs_seconds": round(wall, 1),
        "jobs_cpu_seconds": round(cpu, 1),
        "cpu_per_wall": round(cpu / wall, 2) if wall else None,
        "note": "sums of the jobs' own times: jobs that ran side by side count each",
        "stages": stages,
        "jobs": jobs,
    }
    Path(out_json).write_text(json.dumps(doc, indent=1), encoding="utf-8")
    if out_png is not None:
        plot(doc, out_png)
    return doc


def plot(doc: dict, png: Path) -> None:
    """Left: wall and CPU minutes per stage. Right: each round's wall minutes by stage."""
    plt = pyplot()
    stages = sorted(doc["stages"], key=lambda k: -doc["stages"][k]["seconds"])
    fig, (a, b) = plt.subplots(1, 2, figsize=(13, 5))
    y = range(len(stages))
    a.barh([i + 0.2 for i in y], [doc["stages"][k]["seconds"] / 60 for k in stages], 0.4,
           label="wall")  # fmt: skip
    a.barh([i - 0.2 for i in y], [doc["stages"][k]["cpu_seconds"] / 60 for k in stages], 0.4,
           label="CPU", color="tab:gray")  # fmt: skip
    a.set_yticks(list(y), [f"{k} (x{doc['stages'][k]['jobs']})" for k in stages])
    a.invert_yaxis()
    a.set_xlabel("minutes (summed over the stage's jobs)")
    a.set_title(f"{doc['jobs_seconds'] / 60:.1f} min of jobs, CPU/wall {doc['cpu_per_wall']}")
    a.legend()
    rounds = sorted({j["round"] for j in doc["jobs"] if j["round"] is not None})
    bottom = [0.0] * len(rounds)
    for k in stages:
        mins = [sum((j["seconds"] or 0) / 60 for j in doc["jobs"]
                    if j["stage"] == k and j["round"] == r) for r in rounds]  # fmt: skip
        if any(mins):
            b.bar(rounds, mins, bottom=bottom, label=k)
            bottom = [u + v for u, v in zip(bottom, mins, strict=True)]
    b.set_xlabel("round")
    b.set_ylabel("wall minutes")
    b.set_title("per round (the stages after the rounds are on the left only)")
    b.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(png, dpi=90)
    plt.close(fig)
