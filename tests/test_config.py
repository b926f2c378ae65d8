"""The typed config: defaults, validation messages, the generated JSON schema."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import pytest
import yaml

from scenebot.config import SCHEMA_PATH, ConfigError, json_schema, load_config, validate_config

ROOT = Path(__file__).resolve().parents[1]


def test_committed_schema_matches_the_model():
    committed = json.loads(SCHEMA_PATH.read_text())
    assert committed == json.loads(json.dumps(json_schema())), (
        "scenebot/config.schema.json is stale: run `scenebot schema --write`"
    )


def test_default_config_file_is_valid_and_passes_the_schema():
    cfg = load_config(ROOT / "config.yaml")
    assert cfg.scene == "office" and cfg.robot == "sim"
    assert cfg.exploration.photos == 100
    jsonschema.validate(yaml.safe_load((ROOT / "config.yaml").read_text()), json_schema())


def test_a_wrong_literal_names_the_key_and_the_allowed_values():
    with pytest.raises(ConfigError) as e:
        validate_config({"robot": "roomba"})
    assert "robot" in str(e.value) and "'sim'" in str(e.value)


def test_an_out_of_range_value_names_the_key():
    with pytest.raises(ConfigError, match=r"sim\.camera\.width.*greater than or equal to 32"):
        validate_config({"sim": {"camera": {"width": 3}}})


def test_a_misspelt_key_is_reported():
    with pytest.raises(ConfigError, match=r"exploration\.photoz: unknown key"):
        validate_config({"exploration": {"photoz": 10}})


def test_world_needs_exactly_one_source():
    with pytest.raises(ConfigError, match=r"exactly one of world.builtin"):
        validate_config({"world": {"builtin": "office", "file": "room.glb"}})


def test_missing_config_file_is_named(tmp_path):
    with pytest.raises(ConfigError, match=r"nope.yaml not found"):
        load_config(tmp_path / "nope.yaml")


# ------------------------------------------------- stage parameters (issue 24, item 6)
def test_stage_parameters_need_only_the_sections_they_hold():
    """A stage receives only its own sections (Snakemake params): the checks across sections
    (robot: photos needs photos.folder) belong to the whole config, checked at the start."""
    from scenebot.config import from_sections, section_json

    cfg = validate_config({"robot": "photos", "photos": {"folder": "my_photos"}})
    for sections in (("dense",), ("tour",), ("mesh",), ("plan", "sim"), ("goals", "max_rounds")):
        stage = from_sections(section_json(cfg, "scene", "robot", "seed", *sections))
        assert stage.robot == "photos"
        for name in sections:
            assert getattr(stage, name) == getattr(cfg, name)
    sfm = from_sections(section_json(cfg, "scene", "robot", "seed", "sfm", "photos"))
    assert sfm.photos.folder == Path("my_photos")
    with pytest.raises(ConfigError, match=r"robot: photos needs photos\.folder"):
        validate_config({"robot": "photos"})
    with pytest.raises(ConfigError, match=r"robot: photos needs photos\.folder"):
        from_sections(json.dumps({"robot": "photos", "photos": {"folder": None}}))


def test_stage_parameters_keep_the_derived_camera_mount():
    from scenebot.config import from_sections, section_json

    cfg = validate_config({"sim": {"camera": {"forward_offset_m": 0.2}}})
    assert cfg.sfm.camera_offset_m == pytest.approx(0.2)
    assert from_sections(section_json(cfg, "sfm")).sfm.camera_offset_m == pytest.approx(0.2)
    assert from_sections(section_json(cfg, "follow")).follow.camera_forward_m == 0.2


def test_where_the_cache_lives_is_no_stage_parameter():
    """evaluate.cache_dir says where files are kept, not what is computed: out of the rules'
    parameters (changing it re-runs nothing); the stage gets the default back."""
    from scenebot.config import from_sections, section_json

    cfg = validate_config({"evaluate": {"cache_dir": "/somewhere", "headings": 4}})
    text = section_json(cfg, "evaluate")
    assert "cache_dir" not in json.loads(text)["evaluate"] and "/somewhere" not in text
    stage = from_sections(text)
    assert stage.evaluate.headings == 4 and stage.evaluate.cache_dir is None
    assert text == section_json(validate_config({"evaluate": {"headings": 4}}), "evaluate")


# ------------------------------------- values as YAML and --config give them (item 7)
def _schema_ok(data):
    """The check Snakemake runs after validate_config (rules/common.smk)."""
    from snakemake.utils import validate

    validate(data, schema=str(SCHEMA_PATH), set_default=False)


def test_a_quoted_number_is_read_as_the_number_and_the_schema_agrees():
    from scenebot.config import normalize_config

    data = {"exploration": {"photos": "12", "drive_max_m": "2.5"}}
    cfg = validate_config(data)
    assert cfg.exploration.photos == 12 and cfg.exploration.drive_max_m == 2.5
    normal = normalize_config(data, cfg)
    assert normal == {"exploration": {"photos": 12, "drive_max_m": 2.5}}
    _schema_ok(normal)


def test_nested_config_values_given_as_text_are_read_by_type():
    """`snakemake --config 'world={builtin: null, file: room.glb}'` gives every nested value
    as text (Snakemake reads them with YAML's BaseLoader)."""
    from scenebot.config import normalize_config

    data = {
        "world": {"builtin": "null", "file": "room.glb", "start": {"x": "1", "y": "2.5"}},
        "sim": {"camera": {"antialias": "false", "width": "320"}},
        "dense": {"patchmatch": {"neighbors": ["4", "8"]}},
    }
    cfg = validate_config(data)
    assert cfg.world.builtin is None and cfg.world.file == Path("room.glb")
    assert cfg.world.start.x == 1.0 and cfg.sim.camera.antialias is False
    normal = normalize_config(data, cfg)
    assert normal["world"] == {"builtin": None, "file": "room.glb", "start": {"x": 1.0, "y": 2.5}}
    assert normal["dense"]["patchmatch"]["neighbors"] == [4, 8]
    _schema_ok(normal)


@pytest.mark.parametrize(
    ("data", "line"),
    [
        ({"exploration": {"photos": "twelve"}},
         "exploration.photos: got 'twelve'; expected a whole number, e.g. 100"),
        ({"exploration": {"photos": 12.5}},
         "exploration.photos: got 12.5; expected a whole number, e.g. 100"),
        ({"exploration": {"photos": True}},
         "exploration.photos: got True; expected a whole number, e.g. 100"),
        ({"exploration": {"drive_max_m": "far"}},
         "exploration.drive_max_m: got 'far'; expected a number, e.g. 1.5"),
        ({"exploration": {"drive_max_m": float("nan")}},
         "exploration.drive_max_m: got nan; expected a number, e.g. 1.5"),
        ({"sim": {"camera": {"antialias": "maybe"}}},
         "sim.camera.antialias: got 'maybe'; expected true or false"),
        ({"scene": 2026}, "scene: got 2026; expected text, e.g. 'office' (quote it)"),
        ({"sim": {"camera": {"width": 3}}},
         "sim.camera.width: got 3; must be greater than or equal to 32"),
        ({"sim": 5}, "sim: got 5; expected a section of keys (a mapping)"),
    ],
)  # fmt: skip
def test_every_error_is_one_line_naming_the_key_and_the_fix(data, line):
    with pytest.raises(ConfigError) as e:
        validate_config(data)
    lines = str(e.value).splitlines()
    assert lines[1:] == [f"  - {line}"], str(e.value)


def _check_config(path):
    import subprocess
    import sys

    cmd = [sys.executable, "-m", "scenebot", "check-config", str(path)]
    return subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)


def test_check_config_agrees_with_the_workflow(tmp_path):
    good = tmp_path / "good.yaml"
    good.write_text('exploration:\n  photos: "12"\n')
    res = _check_config(good)
    assert res.returncode == 0 and "valid" in res.stdout, res.stderr
    bad = tmp_path / "bad.yaml"
    bad.write_text("exploration:\n  photos: twelve\n")
    res = _check_config(bad)
    assert res.returncode == 2
    assert "exploration.photos: got 'twelve'; expected a whole number" in res.stderr
    assert "Traceback" not in res.stderr


def test_check_config_names_a_missing_or_non_yaml_file(tmp_path):
    res = _check_config(tmp_path / "nope.yaml")
    assert res.returncode == 2 and "nope.yaml not found" in res.stderr
    broken = tmp_path / "broken.yaml"
    broken.write_text("exploration: [photos\n")
    res = _check_config(broken)
    assert res.returncode == 2 and "broken.yaml: not valid YAML" in res.stderr
    text = tmp_path / "notes.txt"
    text.write_text("just some text\n")
    res = _check_config(text)
    assert res.returncode == 2
    assert "notes.txt: not a config file: expected keys and values" in res.stderr
    assert "Traceback" not in res.stderr


# ------------------------------------------------------ robot sections (item 7)
def test_a_capture_reads_only_the_sections_of_its_robot():
    """A changed nxt: setting must not re-take the photos of robot: sim."""
    assert set(validate_config({}).robot_sections()) == {"world", "sim"}
    assert "world" not in validate_config({"robot": "nxt"}).robot_sections()
    assert {"nxt", "nxt_emulator", "world", "sim"} == set(
        validate_config({"robot": "nxt-emulated"}).robot_sections()
    )


def test_config_keys_named_in_robot_messages_exist():
    """Messages of the robot package name config keys as written in config.yaml
    (`nxt.port`, not `robot.nxt.port`)."""
    import io
    import re
    import tokenize

    from pydantic import BaseModel

    from scenebot.config import Config

    key = re.compile(r"(?<![\w./~-])((?:robot\.)?nxt(?:_emulator)?(?:\.[a-z_][a-z0-9_]*)+)")
    section = re.compile(r"(?<![\w./~-])robot\.nxt(?:_emulator)?\b")
    named = set()
    for f in sorted((ROOT / "scenebot").rglob("*.py")):
        for tok in tokenize.generate_tokens(io.StringIO(f.read_text()).readline):
            if tok.type == tokenize.STRING:
                where = f"{f.name}:{tok.start[0]}"
                named |= {(m.group(1), where) for m in key.finditer(tok.string)}
                named |= {(m.group(0), where) for m in section.finditer(tok.string)}
    assert named
    bad = []
    for dotted, where in sorted(named):
        node: object = Config()
        for part in dotted.split("."):
            if not isinstance(node, BaseModel) or part not in type(node).model_fields:
                bad.append(f"{dotted} ({where})")
                break
            node = getattr(node, part)
    assert not bad, f"config keys that do not exist: {bad}"
