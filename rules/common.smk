# Helpers shared by all rules: config validation, stage parameters, code inputs.
import sys
from pathlib import Path

from snakemake.utils import validate

from scenebot.config import ConfigError, section_json, validate_config

# A wrong value stops the workflow here, naming the key and the allowed values
# (the typed model first, for its messages; then the JSON schema generated from it).
try:
    CFG = validate_config(config, "the workflow config (config.yaml and --config)")
except ConfigError as exc:
    raise WorkflowError(str(exc)) from None
validate(config, schema="../scenebot/config.schema.json", set_default=False)

PY = sys.executable  # there is no bare `python` on PATH outside the virtualenv
SCENE = CFG.scene
RESULTS = f"results/{SCENE}"
PKG = Path(workflow.basedir) / "scenebot"

# The code each stage runs: a change re-runs exactly the stages that use it.
STAGE_CODE = {
    "capture": [
        "__init__.py",
        "capture.py",
        "capturelog.py",
        "cli.py",
        "config.py",
        "explore.py",
        "jpeg.py",
        "robot",
        "scene",
        "sim",
    ],
}


def stage_code(stage):
    """The package files a stage depends on (inputs, so code changes re-run it)."""
    files = []
    for name in STAGE_CODE[stage]:
        p = PKG / name
        files += sorted(str(f) for f in p.rglob("*.py")) if p.is_dir() else [str(p)]
    return files


def stage_params(*sections):
    """The config sections a stage reads, as canonical JSON (a change re-runs it)."""
    return section_json(CFG, "scene", "robot", "seed", *sections)


def campaign_targets():
    return [
        f"{RESULTS}/round_000/capture/log.jsonl",
        f"{RESULTS}/round_000/capture/trajectory.png",
    ]
