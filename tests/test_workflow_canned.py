"""The committed canned office photos through every stage of the workflow (a file of its
own: a minutes-long unit of work that CI's parallel workers hand out by itself)."""

from __future__ import annotations

import base64
import json
import shutil
import subprocess

import pytest
import yaml

from tests.fixtures.workflow import (
    CANNED,
    CANNED_SFM,
    CAPTURE,
    ROOT,
    SMALL,
    SNAKEMAKE,
    report_data,
    snakemake,
    why,
)


@pytest.mark.slow
@pytest.mark.skipif(not (CANNED / "log.jsonl").exists(), reason="canned photo set missing")
def test_every_stage_runs_on_the_canned_photo_set(workdir):
    """The committed 320x240 office photos through every stage: round 0's map and decisions,
    an adaptive round in the simulator, the campaign summary and the dense model; then a
    changed decision stage rebuilds the maps but never re-takes a finished round's photos."""
    cfg = dict(
        SMALL,
        max_rounds=2,
        sim={"camera": {"width": 320, "height": 240}},
        sfm=CANNED_SFM,
        score={"n_candidates": 300},
        goals={"k": 3},
        adaptive={"fan_photos": 3},
        dense={"max_image_size": 320},
        tour={"width": 160, "height": 120, "eval_holdout": 4, "path": {"frames": 24}},
        evaluate={"validity_candidates": 24, "validity_width": 160, "validity_height": 120},
    )
    (workdir / "config.yaml").write_text(yaml.safe_dump(cfg))
    capture = workdir / "results/office/round_000/capture"
    shutil.copytree(CANNED, capture)
    # the photos are given: mark the capture up to date instead of taking new ones
    trajectory = capture / "trajectory.png"
    if not trajectory.exists():
        from scenebot.capture.stage import plot_trajectory

        plot_trajectory(capture / "log.jsonl", trajectory)
    touched = snakemake(workdir, "--touch", *CAPTURE)
    assert touched.returncode == 0, why(touched, workdir)
    res = snakemake(workdir)
    assert res.returncode == 0, why(res, workdir)
    assert not (capture / "superseded").exists()  # the given photos were not re-taken
    results = workdir / "results/office"
    r0 = results / "round_000"
    products = "sfm/images.bin sfm/point_descriptors.npz sfm/map.png mesh.ply freespace.png"
    products += " candidates.csv goals.json paths.json navgrid.png"
    for name in products.split():
        assert (r0 / name).stat().st_size > 0, name
    goals = json.loads((r0 / "goals.json").read_text())
    assert "complete" in goals and goals["goals"]
    campaign = json.loads((results / "campaign.json").read_text())
    rounds = [r["round"] for r in campaign["rounds"]]
    assert rounds == ([0] if goals["complete"] else [0, 1])
    last_goals = json.loads((results / f"round_{rounds[-1]:03d}" / "goals.json").read_text())
    # the last round's goals.json may say complete (diminishing returns) at max_rounds too
    stop = "complete" if last_goals["complete"] else "max_rounds = 2 reached"
    assert stop in campaign["stopped_because"], campaign["stopped_because"]
    if rounds == [0, 1]:
        r1 = results / "round_001"
        events = [json.loads(x) for x in (r1 / "capture/log.jsonl").read_text().splitlines()]
        outcomes = [e for e in events if str(e.get("event", "")).startswith("goal_")]
        primary = [e for e in outcomes if "backup_for" not in e]
        assert len(primary) == len(goals["goals"])  # every goal reached, abandoned or skipped
        assert all(e.get("reason") for e in outcomes)
        assert (r1 / "capture/trajectory.png").stat().st_size > 0
        assert (r1 / "sfm/report.json").exists() and (r1 / "paths.json").exists()
        assert campaign["rounds"][1]["photos"] == len(list((r1 / "capture/images").glob("*")))
    assert (results / "campaign.png").stat().st_size > 0
    assert (results / "final/dense/fused.ply").stat().st_size > 1000
    tour = results / "final/tour"
    assert (tour / "index.html").is_file() and (tour / "tour.mp4").stat().st_size > 1000
    summary = json.loads((tour / "tour_summary.json").read_text())
    frames = len(list((tour / "frames").glob("*.jpg")))
    assert frames == summary["frames"] >= 4  # frames seeing too little are dropped, said so
    assert frames + summary["path_dropped_frames"] == 24
    final = json.loads((results / "final/evaluation.json").read_text())
    assert final  # the truth-based figures of the campaign
    for r in rounds:
        assert (results / f"round_{r:03d}/evaluation.json").is_file()
    assert (results / "eval/observable_surface.png").is_file()
    validity = json.loads((results / "final/score_validity.json").read_text())
    assert 3 <= validity["candidates"] <= 24
    assert -1.0 <= validity["spearman_score_psnr"] <= 1.0
    assert len(validity["rows"]) == validity["candidates"]
    assert snakemake(workdir, "-n").stdout.count("Nothing to be done") == 1

    # the HTML report: every stage's pictures, the tables, the tour video, the rule graph
    html = workdir / "report.html"
    # exactly the README's command: no --cores (Snakemake needs none to write a report)
    cmd = [*SNAKEMAKE, "-s", str(ROOT / "Snakefile"), "-d", str(workdir), "--report", str(html)]
    built = subprocess.run(cmd, capture_output=True, text=True, cwd=workdir, timeout=900)
    assert built.returncode == 0, built.stderr[-4000:]
    page = html.read_text(encoding="utf-8")
    entries = report_data(page, "results")
    expected = {"campaign.png", "campaign.json", "eval/observable_surface.png"}
    expected |= {"final/tour/tour.mp4", "final/evaluation.png"}
    expected.add("final/score_validity.png")
    expected |= {f"final/dense/{f}.png" for f in ("fused_views", "depth_normal_mosaic", "planes")}
    for r in rounds:
        d = f"round_{r:03d}"
        expected |= {f"{d}/{f}" for f in ("sfm/map.png", "evaluation.png", "candidates.csv")}
        expected |= {f"{d}/{f}.png" for f in ("freespace", "score_views", "goals", "navgrid")}
        expected.add(f"{d}/capture/trajectory.png")
    for name in sorted(expected):
        entry = entries.get(f"results/office/{name}")
        assert entry is not None, f"{name} not in the report: {sorted(entries)}"
        assert entry["caption"].strip(), f"{name} has no caption"
        data = base64.b64decode(entry["data_uri"].split("base64,", 1)[1])
        assert data == (results / name).read_bytes(), f"{name} embedded wrong"
    assert entries["results/office/final/tour/tour.mp4"]["mime_type"] == "video/mp4"
    assert "round 000" in entries["results/office/round_000/sfm/map.png"]["caption"]
    graph = report_data(page, "rulegraph")["data"][0]["values"]
    assert {"capture_round0", "sfm", "plan", "campaign", "dense", "tour"} <= {
        node["rule"] for node in graph
    }

    # a decision stage changes: maps and decisions are rebuilt, photos are kept
    photos = {p: p.stat().st_mtime_ns for p in results.glob("round_*/capture/images/*.jpg")}
    (workdir / "config.yaml").write_text(yaml.safe_dump(dict(cfg, score={"n_candidates": 250})))
    again = snakemake(workdir)
    assert again.returncode == 0, why(again, workdir)
    assert "rule score" in again.stdout + again.stderr
    assert "capture" not in "".join(
        line for line in (again.stdout + again.stderr).splitlines() if line.startswith("rule ")
    )
    assert {p: p.stat().st_mtime_ns for p in photos} == photos
    assert not list(results.glob("round_*/capture/superseded"))
