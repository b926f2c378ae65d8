"""The Snakemake workflow end to end: runs, re-runs nothing, re-runs exactly what changed."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from tests.fixtures.workflow import CANNED, CAPTURE, ROOT, SMALL, snakemake, why


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


@pytest.mark.slow
def test_two_campaigns_share_the_observable_surface_and_its_folder_reruns_nothing(workdir):
    """Rule observable in two campaign folders of the same scene and settings: the second
    copies the first's surface from the shared cache (its log says so, naming the file and the
    key's hash). Where the cache lives is no parameter: changing it re-runs nothing, while a
    setting of the surface does."""
    target = "results/office/eval/observable_surface.npz"
    fast = {"grid_step_m": 0.6, "headings": 3, "sample_spacing_m": 0.08}
    cache = workdir / "cache"
    cfg = dict(SMALL, evaluate=dict(fast, cache_dir=str(cache)))
    second = workdir / "second"
    second.mkdir()
    logs = []
    for folder in (workdir, second):
        (folder / "config.yaml").write_text(yaml.safe_dump(cfg))
        res = snakemake(folder, target)
        assert res.returncode == 0, why(res, folder)
        logs.append((folder / "results/office/logs/observable.log").read_text())
    (shared,) = (cache / "observable").glob("observable_surface-v*.npz")
    digest = shared.stem.rsplit("-", 1)[1]
    assert "observable surface computed" in logs[0] and str(shared) in logs[0]
    assert "from the shared cache" in logs[1] and str(shared) in logs[1] and digest in logs[1]
    with np.load(workdir / target) as a, np.load(second / target) as b:
        assert np.array_equal(a["observable"], b["observable"])
        assert np.array_equal(a["points"], b["points"])

    (second / "config.yaml").write_text(
        yaml.safe_dump(dict(cfg, evaluate=dict(fast, cache_dir="")))
    )
    res = snakemake(second, "-n", target)
    assert res.returncode == 0 and "Nothing to be done" in res.stdout + res.stderr
    (second / "config.yaml").write_text(yaml.safe_dump(dict(cfg, evaluate=dict(fast, headings=4))))
    res = snakemake(second, "-n", "-p", target)
    out = res.stdout + res.stderr
    assert res.returncode == 0 and "Params have changed" in out
    # without evaluate.cache_dir the stage follows SCENEBOT_CACHE (no --cache-dir)
    assert "-m scenebot observable" in out and "--cache-dir" not in out
