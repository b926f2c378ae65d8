"""Each stage's command takes one option per file it reads and writes (scenebot/cli.py's
STAGE_FILES), exactly the fields of the stage's inputs and outputs dataclasses, and its rule
names every one of those files."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest

from scenebot import cli

REPO = Path(__file__).resolve().parents[1]
STAGES = {
    "sfm": ("scenebot.sfm.stage", "SfmInputs", "SfmOutputs"),
    "mesh": ("scenebot.mesh.stage", "MeshInputs", "MeshOutputs"),
    "score": ("scenebot.score.stage", "ScoreInputs", "ScoreOutputs"),
    "goals": ("scenebot.goals.stage", "GoalsInputs", "GoalsOutputs"),
    "plan": ("scenebot.plan.stage", "PlanInputs", "PlanOutputs"),
    "goals-preview": ("scenebot.goals.preview", "PreviewInputs", "PreviewOutputs"),
    "guide-page": ("scenebot.guide.page", "GuideInputs", "GuideOutputs"),
    "guide-fulfilment": ("scenebot.guide.fulfil", "FulfilInputs", "FulfilOutputs"),
}
RULES = {"goals-preview": "goals_preview", "guide-page": "guide", "guide-fulfilment": "fulfilment"}
"""The rule of a command named otherwise."""


def spec(cls) -> list[str]:
    """A dataclass's fields as STAGE_FILES writes them (``?`` optional, ``*`` a list)."""
    out = []
    for f in dataclasses.fields(cls):
        if f.default_factory is not dataclasses.MISSING:
            out.append(f.name + "*")
        elif f.default is not dataclasses.MISSING:
            out.append(f.name + "?")
        else:
            out.append(f.name)
    return out


@pytest.mark.parametrize("stage", sorted(STAGES))
def test_the_options_are_the_dataclass_fields(stage):
    import importlib

    module, ins, outs = STAGES[stage]
    mod = importlib.import_module(module)
    assert list(cli.STAGE_FILES[stage]) == spec(getattr(mod, ins)) + spec(getattr(mod, outs))


@pytest.mark.parametrize("stage", sorted(STAGES))
def test_the_rule_names_every_required_file(stage):
    text = "\n".join(p.read_text(encoding="utf-8") for p in (REPO / "rules").glob("*.smk"))
    name = RULES.get(stage, stage)
    rule = re.search(
        rf"\n(?:rule|checkpoint) {name}:\n(.*?)(?=\n(?:rule|checkpoint) |\Z)", text, re.S
    )
    assert rule, stage
    for name in cli.STAGE_FILES[stage]:
        if name.endswith(("?", "*")):
            continue  # optional: given where the round has one (a previous round, a picture)
        assert f"--{name.replace('_', '-')} " in rule.group(1), (stage, name)


def test_the_parser_builds_the_dataclasses(tmp_path):
    from scenebot.goals.stage import GoalsInputs, GoalsOutputs

    args = cli.build_parser().parse_args(
        ["goals", "--candidates-csv", "c.csv", "--freespace-npz", "f.npz",
         "--goals-json", "g.json"]
    )  # fmt: skip
    assert cli.files(args, GoalsInputs) == GoalsInputs(Path("c.csv"), Path("f.npz"))
    assert cli.files(args, GoalsOutputs) == GoalsOutputs(Path("g.json"))


def test_a_missing_file_option_names_it(capsys):
    with pytest.raises(SystemExit):
        cli.build_parser().parse_args(["mesh", "--sfm-dir", "x"])
    assert "--mesh-ply" in capsys.readouterr().err


def test_building_the_parser_imports_no_stage():
    import subprocess
    import sys

    code = (
        "import sys; from scenebot import cli; cli.build_parser(); "
        "print(sorted(m for m in sys.modules if m.endswith('.stage')))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout
