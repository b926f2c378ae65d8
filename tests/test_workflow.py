"""The Snakemake workflow end to end: runs, re-runs nothing, re-runs exactly what changed."""

from __future__ import annotations

import base64
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
SNAKEMAKE = [sys.executable, "-m", "snakemake"]
# round-0 capture only: 12 small photos are too few for the later stages
CAPTURE = (
    "results/office/round_000/capture/log.jsonl",
    "results/office/round_000/capture/trajectory.png",
)

SMALL = {
    "scene": "office",
    "sim": {"camera": {"width": 160, "height": 120}},
    "exploration": {"photos": 12},
}


def snakemake(workdir: Path, *args: str) -> subprocess.CompletedProcess:
    cmd = [*SNAKEMAKE, "-s", str(ROOT / "Snakefile"), "-d", str(workdir), "--cores", "2", *args]
    return subprocess.run(cmd, capture_output=True, text=True, cwd=workdir, timeout=900)


def why(res: subprocess.CompletedProcess, workdir: Path) -> str:
    """What a failed run said: the end of its stderr, then the end of each failed rule's log
    (Snakemake's own message of a failed rule is mostly its shell command, and a long one
    pushes the rule's error out of the stderr's tail)."""
    logs = re.findall(r"log: (\S+) \(check log file", res.stderr)
    text = [res.stderr[-2000:]]
    for name in dict.fromkeys(logs):
        path = workdir / name
        tail = path.read_text(errors="replace")[-3000:] if path.is_file() else "(missing)"
        text.append(f"--- {name} ---\n{tail}")
    return "\n".join(text)


@pytest.fixture
def workdir(tmp_path):
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(SMALL))
    return tmp_path


@pytest.mark.slow
def test_workflow_runs_then_has_nothing_to_do_then_reruns_what_changed(workdir):
    first = snakemake(workdir, *CAPTURE)
    assert first.returncode == 0, why(first, workdir)
    capture = workdir / "results/office/round_000/capture"
    assert len(list((capture / "images").glob("*.jpg"))) == 12
    assert (capture / "trajectory.png").is_file()
    assert (workdir / "results/office/benchmarks/capture_round0.tsv").is_file()

    again = snakemake(workdir, "-n", *CAPTURE)
    assert again.returncode == 0
    assert "Nothing to be done" in again.stdout + again.stderr

    cfg = dict(SMALL, sim={"camera": {"width": 160, "height": 120}, "slip": {"turn": 0.05}})
    (workdir / "config.yaml").write_text(yaml.safe_dump(cfg))
    changed = snakemake(workdir, "-n", *CAPTURE)
    assert changed.returncode == 0
    out = changed.stdout + changed.stderr
    assert "capture_round0" in out and "Params have changed" in out

    rerun = snakemake(workdir, *CAPTURE)
    assert rerun.returncode == 0, why(rerun, workdir)
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


@pytest.mark.slow
def test_round0_capture_through_the_nxt_driver_and_the_brick_emulator(workdir):
    """robot: nxt-emulated: the exact bytes of the hardware path, the same artifacts."""
    cfg = dict(SMALL, robot="nxt-emulated", exploration={"photos": 8})
    cfg["nxt_emulator"] = {"time_scale": 4.0}
    (workdir / "config.yaml").write_text(yaml.safe_dump(cfg))
    res = snakemake(workdir, f"{'results/office/round_000/capture/log.jsonl'}")
    assert res.returncode == 0, why(res, workdir)
    capture = workdir / "results/office/round_000/capture"
    records = [json.loads(line) for line in (capture / "log.jsonl").read_text().splitlines()]
    assert records[0]["robot"] == "nxt-emulated"
    photos = [r for r in records if r["type"] == "photo"]
    assert len(photos) == 8 and len(list((capture / "images").glob("*.jpg"))) == 8
    assert all({"odometry", "compass_deg", "ultrasonic_cm", "truth"} <= p.keys() for p in photos)
    assert (capture / "trajectory.png").is_file()
    assert not any((capture / "inbox").iterdir())  # every photo moved, none left behind


CANNED = ROOT / "tests" / "data" / "canned" / "round_000" / "capture"


def report_data(html: str, script: str) -> dict:
    """The JSON a Snakemake HTML report embeds as `<script id="{script}">var x = {...};`:
    "results" (by path: name, caption as HTML, mime type, the file as a base64 data URI),
    "categories", "rulegraph" (a Vega spec)."""
    text = html.split(f'<script id="{script}">', 1)[1].split("=", 1)[1]
    return json.JSONDecoder().raw_decode(text.lstrip())[0]


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
        sfm={"peak_threshold": 0.002},
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


@pytest.mark.slow
@pytest.mark.skipif(not (CANNED / "log.jsonl").exists(), reason="canned photo set missing")
def _photo_folder(folder: Path) -> tuple[Path, dict, dict]:
    """The canned photos copied into ``folder`` as a person's photo folder: the folder, its
    files' bytes (to check nothing is modified) and a ``robot: photos`` config for it."""
    folder.mkdir()
    for p in sorted((CANNED / "images").glob("*.jpg")):
        shutil.copy(p, folder / p.name)
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    cfg = dict(SMALL, robot="photos", photos={"folder": str(folder)})
    cfg["sfm"] = {"peak_threshold": 0.002, "exhaustive_max_images": 60}  # no odometry: all pairs
    return folder, before, cfg


def test_bring_your_own_photos_make_round_0(workdir):
    """robot: photos: a plain folder of JPEGs (no log, no robot) becomes round 0's map."""
    folder, before, cfg = _photo_folder(workdir / "my_photos")
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
    folder, before, cfg = _photo_folder(workdir / "my photos")  # a space, as users have
    cfg["score"] = {"n_candidates": 100}
    cfg["goals"] = {"k": 2}
    cfg["dense"] = {"max_image_size": 160, "plane_fill": {"enabled": False}}
    cfg["tour"] = {"width": 96, "height": 72, "eval_holdout": 0, "path": {"frames": 8}}
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


def _rule_inputs(dry_run: str, rule: str) -> list[str]:
    """The inputs of ``rule`` as a dry run lists them."""
    block = dry_run.split(f"rule {rule}:", 1)[1]
    line = next(x for x in block.splitlines() if x.strip().startswith("input:"))
    return [f.strip() for f in line.split("input:", 1)[1].split(",")]


def test_the_sfm_rule_and_the_photo_reader_agree_on_which_files_are_photos(workdir):
    """One definition of a photo file (suffixes in any case, PNG too, no hidden files), for
    the sfm rule's inputs and the sfm stage's reader; a duplicate is an input but left out
    of the map by the reader (with a warning). A dry run: nothing is computed."""
    from scenebot.sfm.photofiles import photo_files
    from scenebot.sfm.photos import photos_from_folder

    folder = workdir / "my_photos"
    folder.mkdir()
    canned = sorted((CANNED / "images").glob("*.jpg"))
    names = ["0001.jpg", "0002.JPG", "0007.Jpg", "0010.jpeg"]
    for src, name in zip(canned, names, strict=False):
        shutil.copy(src, folder / name)
    from PIL import Image

    with Image.open(canned[5]) as im:
        im.save(folder / "0008.PNG", "PNG")
    shutil.copy(canned[0], folder / "0011.jpg")  # the same photo twice
    (folder / "._0003.jpg").write_bytes(b"\x00\x05\x16\x07")  # macOS metadata, not a photo
    (folder / "notes.txt").write_text("not a photo")
    cfg = dict(SMALL, robot="photos", photos={"folder": str(folder)})
    (workdir / "config.yaml").write_text(yaml.safe_dump(cfg))
    res = snakemake(workdir, "-n", "results/office/round_000/sfm/map.png")
    assert res.returncode == 0, why(res, workdir)
    inputs = {Path(f).name for f in _rule_inputs(res.stdout, "sfm") if str(folder) in f}
    expected = ["0001.jpg", "0002.JPG", "0007.Jpg", "0008.PNG", "0010.jpeg", "0011.jpg"]
    assert [p.name for p in photo_files(folder)] == expected
    assert inputs == set(expected)
    _, photos = photos_from_folder(folder)
    assert [p.name for p in photos] == [n for n in expected if n != "0011.jpg"]


def _capture_params(workdir: Path, cfg: dict) -> dict:
    """The config sections the round-0 capture would receive (a dry run's shell command)."""
    import shlex

    (workdir / "config.yaml").write_text(yaml.safe_dump(cfg))
    res = snakemake(workdir, "-n", "-p", "--forcerun", "capture_round0", CAPTURE[0])
    assert res.returncode == 0, why(res, workdir)
    line = next(x for x in res.stdout.splitlines() if "-m scenebot capture" in x)
    words = shlex.split(line.split("2>", 1)[0])
    return json.loads(words[words.index("--params") + 1])


def test_a_capture_receives_only_the_settings_of_its_robot(workdir):
    """Changing an nxt: or nxt_emulator: setting while robot: sim must not re-take round 0
    (and so every round): those sections are not the capture's params."""
    sim = _capture_params(workdir, SMALL)
    assert set(sim) == {"scene", "robot", "seed", "world", "sim", "exploration"}
    changed = dict(SMALL, nxt={"port": "/dev/rfcomm7"}, nxt_emulator={"time_scale": 2.0})
    assert _capture_params(workdir, changed) == sim
    emulated = _capture_params(workdir, dict(changed, robot="nxt-emulated"))
    assert {"nxt", "nxt_emulator", "world", "sim"} <= set(emulated)
    assert emulated["nxt"]["port"] == "/dev/rfcomm7"


def test_a_quoted_number_and_nested_config_values_run(workdir):
    """`exploration.photos: "12"` in the YAML and `--config 'exploration={photos: 12}'`
    (Snakemake passes nested values as text) start the workflow, as check-config says."""
    text = (workdir / "config.yaml").read_text().replace("photos: 12", 'photos: "12"')
    (workdir / "config.yaml").write_text(text)
    res = snakemake(workdir, "-n", CAPTURE[0])
    assert res.returncode == 0, why(res, workdir)
    nested = snakemake(
        workdir, "-n", CAPTURE[0], "--config", "exploration={photos: 9, drive_max_m: 1.2}",
        "sim={camera: {width: 160, height: 120, antialias: false}}",
    )  # fmt: skip
    assert nested.returncode == 0, why(nested, workdir)
    bad = snakemake(workdir, "-n", CAPTURE[0], "--config", "exploration={photos: many}")
    assert bad.returncode != 0
    out = bad.stdout + bad.stderr
    assert "exploration.photos: got 'many'; expected a whole number, e.g. 100" in out
    assert "Traceback" not in out and "Failed validating" not in out


def test_a_target_read_as_a_config_file_is_named(workdir):
    """Snakemake reads every word after `--configfile` as a config file: a target placed
    there is named as what it is (when Snakemake could read it at all)."""
    (workdir / "my.yaml").write_text(yaml.safe_dump(SMALL))
    report = workdir / "results/office/round_000/sfm/report.json"
    report.parent.mkdir(parents=True)
    report.write_text(json.dumps({"photos": 3, "registered": 3}))
    target = "results/office/round_000/sfm/report.json"
    res = snakemake(workdir, "-n", "--configfile", "my.yaml", target)
    assert res.returncode != 0
    out = res.stdout + res.stderr
    assert f"--configfile got {target}, which is not a config file" in out, out[-2000:]
    assert "targets first" in out
    for args in (("-n", CAPTURE[0], "--configfile", "my.yaml"),
                 ("-n", "--configfile=my.yaml", CAPTURE[0])):  # fmt: skip
        ok = snakemake(workdir, *args)
        assert ok.returncode == 0, why(ok, workdir)


def test_the_readme_gives_config_files_in_an_order_that_works():
    """`--configfile my.yaml <target>` reads the target as a config file."""
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    for line in readme.splitlines():
        m = re.search(r"--configfile\s+(\S+)\s+(\S+)", line)
        assert m is None or m.group(2).startswith(("-", "`")), line
    assert "--configfile=my.yaml" in readme


def test_the_readme_says_what_a_killed_host_leaves_running():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    robots = readme.split("## Robots", 1)[1].split("\n## ", 1)[0]
    assert "SIGKILL" in robots and "tacho limit" in robots
