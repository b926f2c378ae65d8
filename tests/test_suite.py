"""The scene suite: its config, the per-scene campaigns' configs, the summary (median, worst
scene, margins over the baselines) on hand-made evaluations, and (slow) a two-scene
mini-suite through the suite rules."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import time

import pytest
import yaml

from scenebot import cli
from scenebot.config import Config, ConfigError, validate_config
from scenebot.evaluate.config import SuiteConfig
from scenebot.evaluate.suite import (
    SuiteError,
    SuiteInputs,
    SuiteOutputs,
    run,
    scene_configs,
    scene_files,
)
from tests.fixtures.workflow import (
    CANNED,
    CANNED_SFM,
    ROOT,
    SMALL,
    SNAKEMAKE,
    small_final_stages,
    snakemake,
    why,
)


def evaluation(comp2: float, photos: int = 40, registered: int = 38, reached: int = 3) -> dict:
    """A final evaluation.json with the figures the suite reads."""
    dense = {
        "2cm": {"accuracy": 0.9, "completeness": comp2, "fscore": 0.8},
        "5cm": {"accuracy": 0.95, "completeness": comp2 + 0.05, "fscore": 0.85},
        "breakdown": {"photographed_share": 0.7},
    }
    return {
        "capture": {"photos_total": photos},
        "sfm": {"registered": registered},
        "goals_truth": {"reachable": 4, "reached_within": reached,
                        "reached_within_fraction_of_reachable": reached / 4},
        "dense": dense,
    }  # fmt: skip


def baselines(random2: float, frontier2: float) -> dict:
    return {
        m: {"photos": 40, "dense": {"2cm": {"completeness": c, "accuracy": 0.9, "fscore": 0.8}}}
        for m, c in (("random", random2), ("frontier", frontier2))
    }


def write_suite(tmp_path, scenes: dict[str, tuple[dict, dict]]) -> tuple[SuiteInputs, SuiteOutputs]:
    ins = SuiteInputs()
    for name, (ev, base) in scenes.items():
        d = tmp_path / name
        d.mkdir()
        (d / "evaluation.json").write_text(json.dumps(ev))
        (d / "baselines.json").write_text(json.dumps(base))
        ins.evaluations.append(d / "evaluation.json")
        ins.baselines.append(d / "baselines.json")
    out = SuiteOutputs(tmp_path / "suite.json", tmp_path / "suite.md", tmp_path / "suite.png")
    return ins, out


def test_the_default_suite_is_office_flat_and_six_generated_rooms():
    scenes = Config().suite.scenes
    assert [s.name for s in scenes] == ["office", "flat"] + [f"rooms{k}" for k in range(1, 7)]
    from scenebot.scene.rooms import describe

    kinds = [describe(s.seed)["kind"] for s in scenes if s.builtin == "rooms"]
    assert "L" in kinds and any(k.startswith("two rooms") for k in kinds)


def test_a_suite_scene_needs_one_world_and_a_unique_name():
    with pytest.raises(ConfigError, match="exactly one of builtin"):
        validate_config({"suite": {"scenes": [{"name": "a"}]}})
    with pytest.raises(ConfigError, match="given twice: a"):
        validate_config({"suite": {"scenes": [{"name": "a", "builtin": "office"}] * 2}})
    with pytest.raises(ConfigError, match=r"suite\.scenes\.0\.name"):
        validate_config({"suite": {"scenes": [{"name": "a b", "builtin": "office"}]}})


def test_each_scene_runs_the_workflow_settings_in_its_own_world():
    config = {"scene": "temple", "robot": "photos", "photos": {"folder": "x"},
              "world": {"builtin": "office", "start": {"x": 1, "y": 1}},
              "goals": {"k": 3},
              "evaluate": {"reference_cameras": "cams.txt", "cache_dir": "cache"}}  # fmt: skip
    suite = SuiteConfig(scenes=[
        {"name": "a", "builtin": "rooms", "seed": 2},
        {"name": "b", "file": "room.glb", "overrides": {"goals": {"k": 4}}},
    ])  # fmt: skip
    cfgs = scene_configs(config, suite)
    assert list(cfgs) == ["a", "b"]
    a, b = cfgs["a"], cfgs["b"]
    assert a["scene"] == "suite/a" and a["robot"] == "sim" and "photos" not in a
    assert a["world"] == {"builtin": "rooms", "file": None, "seed": 2}  # no start of another
    assert a["goals"] == {"k": 3} and b["goals"] == {"k": 4}
    assert a["suite"] == {"scenes": [], "baselines": ["random", "frontier"]}  # one campaign
    assert "reference_cameras" not in a["evaluate"]
    assert a["evaluate"]["cache_dir"] == b["evaluate"]["cache_dir"] == "cache"  # one cache
    assert validate_config(a).scene == "suite/a"
    assert config["robot"] == "photos"  # the workflow's config is left as it was
    assert scene_files(cfgs, "x.json") == ["results/suite/a/x.json", "results/suite/b/x.json"]


def test_the_summary_has_each_scene_the_median_and_the_worst(tmp_path):
    ins, out = write_suite(tmp_path, {
        "a": (evaluation(0.80), baselines(0.60, 0.70)),
        "b": (evaluation(0.50, reached=1), baselines(0.45, 0.55)),
        "c": (evaluation(0.90, registered=40), baselines(0.70, 0.85)),
    })  # fmt: skip
    run(["a", "b", "c"], ins, out)
    doc = json.loads(out.suite_json.read_text())
    rows = {r["scene"]: r for r in doc["scenes"]}
    assert list(rows) == ["a", "b", "c"]
    assert rows["a"]["completeness_2cm"] == 0.80 and rows["a"]["fscore_5cm"] == 0.85
    assert rows["a"]["margin_random"] == pytest.approx(20.0)
    assert rows["b"]["margin_frontier"] == pytest.approx(-5.0)
    assert rows["b"]["goals_reached"] == 1 and rows["b"]["goals_reachable"] == 4
    assert rows["a"]["registered_fraction"] == pytest.approx(38 / 40)
    assert rows["a"]["seen_2"] == 0.7
    assert doc["median"]["completeness_2cm"] == 0.80
    assert doc["median"]["margin_random"] == pytest.approx(20.0)
    assert doc["worst"]["scene"] == "b"
    assert doc["lowest"]["registered"] == {"value": 38, "scene": "a"}
    md = out.suite_md.read_text()
    assert "| **median** |" in md and "| **worst: b** |" in md and "50.0%" in md
    assert out.suite_png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_missing_scene_file_is_named(tmp_path):
    ins, out = write_suite(tmp_path, {"a": (evaluation(0.8), baselines(0.6, 0.7))})
    ins.evaluations.append(tmp_path / "gone" / "evaluation.json")
    ins.baselines.append(tmp_path / "gone" / "baselines.json")
    with pytest.raises(SuiteError, match=r"suite scene 'gone': no final evaluation"):
        run(["a", "gone"], ins, out)
    with pytest.raises(SuiteError, match="one of each per scene"):
        run(["a"], ins, out)
    (tmp_path / "a" / "evaluation.json").write_text(json.dumps({"dense": {}}))
    with pytest.raises(SuiteError, match=r"suite scene .a.: .* no dense figures"):
        run(["a"], SuiteInputs(ins.evaluations[:1], ins.baselines[:1]), out)


def test_the_command_options_are_the_dataclass_fields_and_the_rule_names_them():
    from tests.test_stage_files import spec

    assert list(cli.STAGE_FILES["suite-report"]) == spec(SuiteInputs) + spec(SuiteOutputs)
    text = (ROOT / "rules" / "suite.smk").read_text(encoding="utf-8")
    rule = re.search(r"\nrule suite_report:\n(.*?)(?=\nrule |\Z)", text, re.S).group(1)
    for name in cli.STAGE_FILES["suite-report"]:
        assert f"--{name.rstrip('*').replace('_', '-')} " in rule, name


def test_suite_baselines_says_which_baselines_run():
    assert Config().suite.baselines == ["random", "frontier"]
    suite = SuiteConfig(scenes=[{"name": "a", "builtin": "office"}], baselines=["random"])
    assert scene_configs({}, suite)["a"]["suite"]["baselines"] == ["random"]
    with pytest.raises(ConfigError, match=r"suite\.baselines"):
        validate_config({"suite": {"baselines": []}})
    with pytest.raises(ConfigError, match="twice"):
        validate_config({"suite": {"baselines": ["random", "random"]}})
    with pytest.raises(ConfigError, match=r"suite\.baselines"):
        validate_config({"suite": {"baselines": ["greedy"]}})


def test_the_suite_is_one_dag_of_every_scene_campaign(workdir):
    """`snakemake -n suite`: each scene's campaign under its own rule names and folder, its
    baselines rule running suite.baselines, the report waiting for all of them; the sizes a
    profile gives a campaign rule by name (profiles/slurm) reach each scene's copy of it."""
    two = [{"name": "a", "builtin": "office"}, {"name": "a_b", "builtin": "rooms", "seed": 2}]
    cfg = dict(SMALL, suite={"scenes": two, "baselines": ["frontier"]},
               evaluate={"cache_dir": "cache"})  # fmt: skip
    (workdir / "config.yaml").write_text(yaml.safe_dump(cfg))
    sizes = ("--set-resources", "dense:mem_mb=3701", "--set-threads", "dense=1", "--")
    res = snakemake(workdir, "-n", "-p", *sizes, "suite")
    assert res.returncode == 0, why(res, workdir)
    out = res.stdout
    jobs = {m.group(1): m.group(2) for m in re.finditer(r"\nrule (\w+):\n(.*?)\n\n", out, re.S)}
    for name in ("a", "a_b"):
        dense = jobs[f"suite_{name}_dense"]
        assert "mem_mb=3701" in dense and "threads:" not in dense, dense  # 1 thread
        assert "threads: 2" in jobs[f"suite_{name}_sfm"]  # its own: every core
    for name in ("a", "a_b"):
        for rule in ("capture_round0", "sfm", "dense", "evaluate_final", "baselines"):
            assert f"rule suite_{name}_{rule}:" in out, (name, rule)
        assert f"results/suite/{name}/round_000/capture/log.jsonl" in out
    assert "rule suite_report:" in out and "results/office" not in out
    cmds = [line for line in out.splitlines() if "-m scenebot baselines " in line]
    assert len(cmds) == 2 and all("--methods frontier " in c for c in cmds), cmds
    # every scene's observable surface goes through the one shared cache (made absolute)
    cmds = [line for line in out.splitlines() if "-m scenebot observable " in line]
    assert len(cmds) == 2, cmds
    assert all(f"--cache-dir {workdir / 'cache'} " in c for c in cmds), cmds
    assert all('"cache_dir"' not in c for c in cmds), cmds  # not in --params


# The mini-suite: two scenes whose round 0 is the committed canned office photos (45 photos,
# 320x240: round 0 of a fresh 320x240 capture of 36 photos left the mesh 6 points), one round,
# the random baseline only (suite.baselines), the cheapest later stages. Both scenes are the
# office: what is proved is the suite's DAG, per-scene folders and a report of real figures,
# not scene variety (the default suite's scenes need full-size campaigns).
MINI = dict(
    small_final_stages(SMALL),
    max_rounds=1,
    sim={"camera": {"width": 320, "height": 240}},
    exploration={"photos": 45, "circle_step_deg": 20.0},  # the canned set's capture settings
    sfm=CANNED_SFM,
    evaluate={"validity_candidates": 0, "sample_spacing_m": 0.05, "grid_step_m": 0.5,
              "headings": 4},
    suite={"scenes": [{"name": "office", "builtin": "office", "seed": 7},
                      {"name": "office2", "builtin": "office", "seed": 7}],
           "baselines": ["random"]},
)  # fmt: skip


def canned_round0(workdir, names: list[str]) -> dict:
    """The canned photos as round 0 of each suite scene, marked up to date (not re-taken);
    returns the photos' modification times."""
    files = []
    for name in names:
        capture = workdir / "results" / "suite" / name / "round_000" / "capture"
        shutil.copytree(CANNED, capture)
        trajectory = capture / "trajectory.png"
        if not trajectory.exists():
            from scenebot.capture.stage import plot_trajectory

            plot_trajectory(capture / "log.jsonl", trajectory)
        files += [str(p.relative_to(workdir)) for p in (capture / "log.jsonl", trajectory)]
    touched = snakemake(workdir, "--touch", *files)
    assert touched.returncode == 0, why(touched, workdir)
    photos = (workdir / "results" / "suite").glob("*/round_000/capture/images/*.jpg")
    return {p: p.stat().st_mtime_ns for p in photos}


@pytest.mark.slow
@pytest.mark.skipif(not (CANNED / "log.jsonl").exists(), reason="canned photo set missing")
def test_a_two_scene_mini_suite_runs_through_the_suite_rules(workdir):
    (workdir / "config.yaml").write_text(yaml.safe_dump(MINI))
    photos = canned_round0(workdir, ["office", "office2"])
    t0 = time.perf_counter()
    # four campaigns (two scenes, each with its random baseline): 24 min on the 2-core
    # machine beside other agents' campaigns (load 6-14), past the fixture's 15 min limit
    cmd = [*SNAKEMAKE, "-s", str(ROOT / "Snakefile"), "-d", str(workdir), "--cores", "2", "suite"]
    res = subprocess.run(cmd, capture_output=True, text=True, cwd=workdir, timeout=2700)
    assert res.returncode == 0, why(res, workdir)
    print(f"mini-suite: {time.perf_counter() - t0:.0f} s")
    suite = workdir / "results" / "suite"
    assert {p: p.stat().st_mtime_ns for p in photos} == photos  # round 0 was not re-taken
    assert not list(suite.glob("*/round_000/capture/superseded"))
    doc = json.loads((suite / "suite.json").read_text())
    rows = {r["scene"]: r for r in doc["scenes"]}
    assert list(rows) == ["office", "office2"]
    for name, row in rows.items():
        ev = json.loads((suite / name / "final" / "evaluation.json").read_text())
        base = json.loads((suite / name / "baselines" / "baselines.json").read_text())
        assert row["photos"] == ev["capture"]["photos_total"] == 45
        assert row["registered"] == ev["sfm"]["registered"] > 0
        assert row["completeness_2cm"] == ev["dense"]["2cm"]["completeness"]
        assert 0 < row["completeness_5cm"] == ev["dense"]["5cm"]["completeness"] <= 1
        assert row["fscore_5cm"] == ev["dense"]["5cm"]["fscore"]
        assert set(base) >= {"adaptive", "random"} and "frontier" not in base  # as asked
        random = base["random"]["dense"]["2cm"]["completeness"]
        assert row["margin_random"] == pytest.approx(100 * (row["completeness_2cm"] - random))
        assert row["margin_frontier"] is None
        # the baseline is a campaign of its own: its photos taken in the simulator, as many
        assert base["random"]["photos"] == 45
        shots = suite / name / "baselines" / "random" / "results" / "suite" / name
        assert len(list(shots.glob("round_000/capture/images/*.jpg"))) == 45
        assert (shots / "final" / "dense" / "fused.ply").is_file()
        assert not (shots / "final" / "tour").exists()  # a baseline needs no tour
    comps = sorted(r["completeness_2cm"] for r in rows.values())
    assert doc["median"]["completeness_2cm"] == pytest.approx(sum(comps) / 2)
    assert doc["worst"]["completeness_2cm"] == comps[0]
    md = (suite / "suite.md").read_text()
    assert "| office2 |" in md and "| **median** |" in md and "| **worst: " in md
    assert (suite / "suite.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not (workdir / "results" / "office").exists()  # the suite's office is its own
    assert "Nothing to be done" in snakemake(workdir, "-n", "suite").stdout
