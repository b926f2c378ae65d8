"""Make the canned CI photo set: ``tests/data/canned/round_000/capture/`` (images, log.jsonl,
sim_state.json: where the simulated robot stopped, for the adaptive round that follows).

45 photos of the built-in simulated office at 320x240, taken by the lead's capture stage
(:func:`scenebot.capture.run_capture`) with config overrides: smaller camera, 36 photos,
20 degree circle steps (two and a half circles, two drives: enough overlap for SfM and a
metric scale). The set is committed; re-run this script only when the simulator changes:

    TI_SKIP_VERSION_CHECK=ON .venv/bin/python tests/data/make_canned.py

The capture's ``session.jsonl`` (a hard link of ``log.jsonl``) and ``trajectory.png`` are
removed to keep the set small.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[2]
CANNED = Path(__file__).resolve().parent / "canned"
OVERRIDES = {
    "sim": {"camera": {"width": 320, "height": 240}},
    "exploration": {"photos": 45, "circle_step_deg": 20.0},
}


def _merge(base: dict, over: dict) -> dict:
    out = dict(base)
    for k, v in over.items():
        out[k] = _merge(out.get(k) or {}, v) if isinstance(v, dict) else v
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=str(REPO / "config.yaml"))
    ap.add_argument("--out", default=str(CANNED / "round_000" / "capture"))
    args = ap.parse_args(argv)
    os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")
    from scenebot.capture.stage import run_capture
    from scenebot.config import validate_config

    data = yaml.safe_load(Path(args.config).read_text())
    cfg = validate_config(_merge(data, OVERRIDES), source=f"{args.config} + canned overrides")
    out = Path(args.out)
    if out.exists():
        for img in out.rglob("*.jpg"):
            img.chmod(0o644)
        shutil.rmtree(out)
    summary = run_capture(cfg, out, 0, progress=False)
    for extra in ("session.jsonl", "trajectory.png"):
        (out / extra).unlink(missing_ok=True)
    shutil.rmtree(out / "superseded", ignore_errors=True)
    size = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
    print(json.dumps(summary), f"{size / 1e6:.2f} MB in {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
