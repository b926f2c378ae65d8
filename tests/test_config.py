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
