"""The baselines' summary and plot: coverage curves per campaign, redrawn without runs."""

from __future__ import annotations

import json

import yaml

from scenebot.evaluate.baselines import _shared_prefix, refresh_baselines


def write_campaign(scene_dir, photos_per_round, seen_2, completeness):
    """A campaign's campaign.json and final/evaluation.json with a coverage curve."""
    (scene_dir / "final").mkdir(parents=True)
    n = sum(photos_per_round)
    rounds = [{"round": r, "registered": n} for r in range(len(photos_per_round))]
    (scene_dir / "campaign.json").write_text(json.dumps(
        {"photos_total": n, "rounds": rounds, "stopped_because": "max_rounds"}))  # fmt: skip
    photos = list(range(5, n + 1, 5))
    cov = {"photos": photos, "seen_1": [min(1.0, s + 0.05) for s in seen_2], "seen_2": seen_2}
    dense = {"points": 10, "2cm": {"accuracy": 0.9, "completeness": completeness}}
    ev = {"capture": {"photos_per_round": photos_per_round, "goals": None}, "dense": dense,
          "coverage_by_photos": cov}  # fmt: skip
    (scene_dir / "final" / "evaluation.json").write_text(json.dumps(ev))


def test_refresh_reads_the_curves_and_redraws_without_running(tmp_path):
    scene_dir = tmp_path / "results" / "office"
    write_campaign(scene_dir, [10, 5], [0.2, 0.4, 0.7], 0.5)
    base = scene_dir / "baselines"
    write_campaign(base / "random" / "results" / "office", [15], [0.2, 0.4, 0.45], 0.4)
    (base / "random" / "config.yaml").write_text(yaml.safe_dump({"scene": "office"}))
    out = base / "baselines.json"
    out.write_text(json.dumps({"seconds": 1234.0}))
    # no frontier campaign: left out; no curve to compute, so no scene is needed
    s = refresh_baselines({"scene": "office"}, scene_dir, out)
    assert set(s) >= {"adaptive", "random"} and "frontier" not in s
    assert s["adaptive"]["coverage_by_photos"]["seen_2"] == [0.2, 0.4, 0.7]
    assert s["random"]["photos_per_round"] == [15]
    assert s["seconds"] == 1234.0 and s["coverage_seconds"] < 1.0
    assert json.loads(out.read_text())["random"]["dense"]["2cm"]["completeness"] == 0.4
    assert out.with_suffix(".png").stat().st_size > 20_000


def test_shared_prefix_is_where_all_curves_agree():
    a = {"photos": [5, 10, 15], "seen_1": [0.1, 0.2, 0.3], "seen_2": [0.0, 0.1, 0.2]}
    b = {"photos": [5, 10, 15], "seen_1": [0.1, 0.2, 0.4], "seen_2": [0.0, 0.1, 0.2]}
    assert _shared_prefix([a, b]) == 10
    assert _shared_prefix([a, a]) == 15
    assert _shared_prefix([a]) == 0 and _shared_prefix([a, {}]) == 0
    c = dict(b, seen_2=[0.05, 0.1, 0.2])
    assert _shared_prefix([a, c]) == 0
    assert _shared_prefix([{"photos": []}, {"photos": []}]) == 0


def test_a_nested_baseline_imports_the_package_beside_its_snakefile(tmp_path, monkeypatch):
    """The baseline's `python -m scenebot` runs in its own folder; the workflow's folder
    goes first on PYTHONPATH so it runs the same code as the adaptive campaign, not an
    installed copy from another checkout."""
    import subprocess

    import pytest

    from scenebot.evaluate import baselines
    from scenebot.evaluate.metrics import EvaluationError

    scene_dir = tmp_path / "results" / "office"
    write_campaign(scene_dir, [10, 5], [0.2, 0.4, 0.7], 0.5)
    workflow = tmp_path / "checkout"
    workflow.mkdir()
    seen = {}

    def fake_run(cmd, **kw):
        seen.update(kw, cmd=cmd)
        return subprocess.CompletedProcess(cmd, 1)

    monkeypatch.setattr(baselines.subprocess, "run", fake_run)
    monkeypatch.setenv("PYTHONPATH", "/elsewhere")
    with pytest.raises(EvaluationError, match="baseline random failed"):
        baselines.run_baselines({"scene": "office"}, scene_dir, scene_dir / "b.json",
                                methods=("random",), snakefile=workflow / "Snakefile")  # fmt: skip
    paths = seen["env"]["PYTHONPATH"].split(":")
    assert paths == [str(workflow.resolve()), "/elsewhere"]
    assert seen["cwd"] == (scene_dir / "baselines" / "random").resolve()
    # the baseline is built up to what the comparison reads: no tour, no score validity
    assert seen["cmd"][-2:] == ["results/office/campaign.json",
                                "results/office/final/evaluation.json"]  # fmt: skip
