"""Property tests of config input: any scalar where a number, text, switch, choice, list or
section is expected gives a valid config, or one message naming the key; the workflow's
checks (typed model, then the JSON schema on the values as read) and `scenebot check-config`
agree."""

from __future__ import annotations

import contextlib
import copy
import datetime as dt
import io
import tempfile
from pathlib import Path

import yaml
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from pydantic import BaseModel

from scenebot.cli import main as scenebot_main
from scenebot.config import (
    SCHEMA_PATH,
    Config,
    ConfigError,
    _model_of,
    normalize_config,
    validate_config,
)

SOURCE = "the workflow config (config.yaml and --config)"


def _keys(model: type[BaseModel] = Config, prefix: tuple = ()) -> list[tuple[str, ...]]:
    """Every key of the config, sections and settings, as paths."""
    out = []
    for name, field in model.model_fields.items():
        out.append((*prefix, name))
        sub = _model_of(field.annotation)
        if sub is not None:
            out += _keys(sub, (*prefix, name))
    return out


KEYS = _keys()

# text a YAML file or a nested --config value gives: numbers, YAML's other spellings, choices
TEXTS = "12 2.5 1e3 1.0e+3 null ~ true False yes off nan .inf -1 0x10 4 8 office flat sim photos"
TEXTS = [*TEXTS.split(), " 3 ", "", "fan", "auto", "cpu", "dlt", "A", "12.0", "[4, 8]", "{a: 1}"]

SCALARS = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(),
    st.integers(min_value=-5, max_value=5000),
    st.floats(),  # nan and infinities included
    st.floats(min_value=-10, max_value=1000),
    st.text(max_size=10),
    st.dates(),  # YAML reads 2026-11-26 as a date
    st.sampled_from(TEXTS),
)


def _required(model: type[BaseModel]) -> dict:
    """Right values for the required keys of a section (world.start needs x and y)."""
    sample = {float: 1.0, int: 1, str: "a.jpg"}
    return {n: sample[f.annotation] for n, f in model.model_fields.items() if f.is_required()}


def _nested(path: tuple[str, ...], value) -> dict:
    """``{path[0]: {path[1]: ... value}}``, with the required siblings of each section."""
    models = [Config]
    for part in path[:-1]:
        models.append(_model_of(models[-1].model_fields[part].annotation))
    data = value
    for part, model in zip(reversed(path), reversed(models), strict=True):
        data = {**_required(model), part: data}
    return data


def _workflow(data: dict) -> tuple[Config | None, str | None]:
    """What rules/common.smk does with Snakemake's `config`: the typed model, the values
    as it read them written back, then Snakemake's JSON-schema validation."""
    from snakemake.utils import validate

    config = copy.deepcopy(data)
    try:
        cfg = validate_config(config, SOURCE)
    except ConfigError as exc:
        return None, str(exc)
    config.update(normalize_config(config, cfg))
    validate(config, schema=str(SCHEMA_PATH), set_default=False)  # raises if they disagree
    assert validate_config(config, SOURCE) == cfg  # the written-back values read the same
    return cfg, None


def _check_config(data: dict) -> tuple[int, str]:
    """`scenebot check-config` on the YAML file of ``data``: exit code and stderr."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "my.yaml"
        path.write_text(yaml.safe_dump(data), encoding="utf-8")
        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            rc = scenebot_main(["check-config", str(path)])
        return rc, err.getvalue()


def _assert_one_message_naming(message: str, path: tuple[str, ...]) -> str:
    lines = message.splitlines()
    assert lines[0].startswith("invalid configuration in"), message
    assert len(lines) == 2, message  # one bad value, one message
    line = lines[1]
    assert line.startswith("  - "), message
    key, _, text = line[4:].partition(": ")
    dotted = ".".join(path)
    # the key itself, or the section whose check names it (world: set exactly one of ...)
    assert (
        key == dotted
        or (dotted.startswith(f"{key}.") and path[-1] in text)
        or (key == "(top level)" and path[-1] in text)
    ), (message, dotted)
    assert text, message
    return line


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(path=st.sampled_from(KEYS), value=SCALARS)
@example(path=("scene",), value=5e-324).via("a subnormal: 0.0 after taichi starts")
@example(path=("sfm", "fix_exif_focal"), value=5e-324).via("the same, for a bool")
def test_any_scalar_gives_a_valid_config_or_one_message_naming_the_key(path, value):
    # as the workflow and check-config do, read the value from a YAML file's text: in a
    # process where taichi has started (it turns on the CPU's flush-to-zero mode), a
    # subnormal such as 5e-324 reads as 0.0, and both must judge the value they read
    data = yaml.safe_load(yaml.safe_dump(_nested(path, value)))
    cfg, message = _workflow(data)
    if cfg is None:
        _assert_one_message_naming(message, path)
        assert "Traceback" not in message and "Failed validating" not in message
    rc, err = _check_config(data)
    if cfg is None:  # the same message, with the file as its source
        assert rc == 2, (data, err)
        assert err.strip().splitlines()[1:] == message.splitlines()[1:], (err, message)
    else:
        assert rc == 0, (data, err)


@settings(max_examples=100, deadline=None)
@given(
    path=st.sampled_from(KEYS),
    value=st.sampled_from(["12", "2.5", "true", "false", "null", "4"]),
)
def test_nested_config_text_reads_as_yaml_would(path, value):
    """Snakemake passes nested --config values as text: a value given as text is accepted
    exactly when the value YAML reads from that text is (`"12"` like 12, `"null"` like null)."""
    as_text, as_yaml = _nested(path, value), _nested(path, yaml.safe_load(value))
    text_cfg, _ = _workflow(as_text)
    yaml_cfg, _ = _workflow(as_yaml)
    if yaml_cfg is not None:
        assert text_cfg == yaml_cfg, (as_text, as_yaml)


def test_dates_and_text_scene_names():
    """A scene named like a date or a number is text only when quoted."""
    assert _workflow({"scene": "2026-11-26"})[0].scene == "2026-11-26"
    _, message = _workflow({"scene": dt.date(2026, 11, 26)})
    assert "scene: got datetime.date(2026, 11, 26); expected text, e.g. 'office' (quote it)" in (
        message
    )
