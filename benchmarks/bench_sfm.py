"""Benchmark of the sfm stage: from-scratch vs round update, with accuracy.

Two capture rounds are needed (``round_000/capture`` and ``round_001/capture`` under one
scene folder). By default they are made here: with the simulator (``--source sim``: the
lead's capture stage, ``--photos0`` and ``--photos1`` photos at the config's resolution) or
the ray-cast synthetic room (``--source synthetic``, small and fast). ``--scene DIR`` reuses
existing captures.

Rows (medians over ``--repeats``):

* ``scratch``: the whole stage on rounds 0..1 with an empty database (the reference);
* ``update``: rounds 0..1 continuing from round 0's model, with round 0's features and
  matches already in the database (the round-update case); ratio = update / scratch.

Acceptance (issue 3): 260 photos at 640x480 on 2 cores: scratch <= 8 min; update adding 60
photos to 200 <= 40 % of scratch::

    TI_SKIP_VERSION_CHECK=ON nice -n 10 .venv/bin/python benchmarks/bench_sfm.py \
        --source sim --photos0 200 --photos1 60 --work /tmp/bench_sfm
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import shutil
import statistics
import time
from pathlib import Path

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")

from scenebot.sfm.config import SfmConfig
from scenebot.sfm.stage import SfmInputs, SfmOutputs, run


def make_sim_rounds(scene: Path, config: Path, photos0: int, photos1: int) -> None:
    import yaml

    from scenebot.capture import run_capture
    from scenebot.config import validate_config

    data = yaml.safe_load(config.read_text())
    for r, n in ((0, photos0), (1, photos1)):
        cap = scene / f"round_{r:03d}" / "capture"
        if (cap / "log.jsonl").exists():
            continue
        data.setdefault("exploration", {})["photos"] = n
        data["seed"] = int(data.get("seed", 1)) + r  # another random walk in round 1
        run_capture(validate_config(data), cap, r, progress=False)


def make_synthetic_rounds(scene: Path) -> None:
    from scenebot.sfm.synthetic import SyntheticRoom, make_capture

    room = SyntheticRoom()
    if not (scene / "round_000/capture/log.jsonl").exists():
        make_capture(scene / "round_000/capture", room, n_spots=3, seed=1)
    if not (scene / "round_001/capture/log.jsonl").exists():
        make_capture(scene / "round_001/capture", room, n_spots=2, start_spot=3, round_index=1,
                     seed=2)  # fmt: skip


def timed_run(cfg, inputs, outputs) -> tuple[float, dict]:
    t = time.perf_counter()
    rep = run(cfg, inputs, outputs)
    return time.perf_counter() - t, rep


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--source", choices=["sim", "synthetic"], default="synthetic")
    ap.add_argument("--scene", help="existing scene folder with round_000 and round_001 captures")
    ap.add_argument("--work", default="/tmp/bench_sfm")
    ap.add_argument("--config", default="config.yaml")
    ap.add_argument("--photos0", type=int, default=200)
    ap.add_argument("--photos1", type=int, default=60)
    ap.add_argument("--repeats", type=int, default=1)
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    work = Path(args.work)
    scene = Path(args.scene) if args.scene else work / "scene"
    if not args.scene:
        if args.source == "sim":
            make_sim_rounds(scene, Path(args.config), args.photos0, args.photos1)
        else:
            make_synthetic_rounds(scene)
    caps = [scene / "round_000/capture", scene / "round_001/capture"]
    cfg = SfmConfig(plots=False)
    rows: dict[str, list[float]] = {"scratch": [], "update": []}
    reports: dict[str, dict] = {}
    for _ in range(args.repeats):
        runs = work / "runs"
        shutil.rmtree(runs, ignore_errors=True)
        db_a = runs / "scratch/database.db"
        s, reports["scratch"] = timed_run(
            cfg, SfmInputs(db_a, caps), SfmOutputs(runs / "scratch/round_001/sfm")
        )
        rows["scratch"].append(s)
        db_b = runs / "update/database.db"
        _, reports["round0"] = timed_run(
            cfg, SfmInputs(db_b, caps[:1]), SfmOutputs(runs / "update/round_000/sfm")
        )
        u, reports["update"] = timed_run(
            cfg,
            SfmInputs(db_b, caps, previous_model=runs / "update/round_000/sfm"),
            SfmOutputs(runs / "update/round_001/sfm"),
        )
        rows["update"].append(u)
    ref = statistics.median(rows["scratch"])
    n0, n = reports["round0"]["photos"], reports["scratch"]["photos"]
    print(f"sfm benchmark: {n0} + {n - n0} photos, repeats={args.repeats}, cores={os.cpu_count()}")
    print(f"{'run':<10}{'median s':>10}{'ratio':>8}{'registered':>12}{'mode':>22}"
          f"{'pos err cm':>12}{'heading deg':>13}{'scale err %':>13}")  # fmt: skip
    for k in ("scratch", "update"):
        rep = reports[k]
        acc = rep["accuracy"]
        med = statistics.median(rows[k])
        print(
            f"{k:<10}{med:>10.1f}{med / ref:>8.2f}{rep['registered']:>7}/{rep['photos']:<4}"
            f"{rep['mapping_mode']:>22}"
            f"{acc.get('position_error_m', {}).get('median', float('nan')) * 100:>12.2f}"
            f"{acc.get('heading_error_deg', {}).get('median', float('nan')):>13.3f}"
            f"{acc.get('metric_scale_error', float('nan')) * 100:>13.2f}"
        )
    print("stage timings (s):")
    for k in ("scratch", "update"):
        print(f"  {k}: " + json.dumps({a: round(b, 1) for a, b in reports[k]["timings_s"].items()}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
