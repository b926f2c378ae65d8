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
        "explore.py",
        "jpeg.py",
        "robot",
        "scene",
        "sim",
    ],
    "sfm": ["sfm", "capturelog.py", "jpeg.py"],
    "mesh": [
        "score/mesh.py",
        "score/freespace.py",
        "score/geometry.py",
        "score/stage.py",
    ],
    "score": ["score"],
    "goals": ["score/goals.py", "score/plots.py", "score/stage.py"],
    "plan": ["plan", "score/geometry.py"],
    "dense": ["dense"],
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


PHOTOS = CFG.robot == "photos"  # bring-your-own photos: round 0 is a folder, no robot


def campaign_targets():
    """What `snakemake` builds by default: the campaign as far as its stages exist."""
    r0 = f"{RESULTS}/round_000"
    captured = (
        [] if PHOTOS else [f"{r0}/capture/log.jsonl", f"{r0}/capture/trajectory.png"]
    )
    return captured + [
        f"{r0}/sfm/map.png",
        f"{r0}/goals.json",
        f"{r0}/goals.png",
        f"{r0}/paths.json",
        f"{r0}/navgrid.png",
        f"{RESULTS}/final/dense/fused.ply",
    ]


def captures_until(wildcards):
    """The capture logs of rounds 0..r (the map of round r uses all of them)."""
    r = int(wildcards.r)
    if PHOTOS and r == 0:
        folder = Path(CFG.photos.folder)
        return sorted(
            str(p) for p in folder.glob("*") if p.suffix.lower() in (".jpg", ".jpeg")
        )
    return [f"{RESULTS}/round_{k:03d}/capture/log.jsonl" for k in range(r + 1)]


def image_root(input):
    """The folder the map's image names are relative to (the scene folder, or the photos)."""
    return CFG.photos.folder if PHOTOS else Path(input.model[0]).parents[2]


def last_round():
    """The round whose map the dense model and the tour use."""
    return "000"
