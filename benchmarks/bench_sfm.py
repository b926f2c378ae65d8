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

``--accuracy-seeds 1 2 3`` instead measures round-0 accuracy (100 photos, default office)
per exploration seed: the default settings (lever-arm scale from ``sim.camera.
forward_offset_m``, EXIF focal fixed, circle priors) against the same run's reference
settings of the previous version (focal refined, odometry scale, no circle priors), both on
the same features and matches::

    TI_SKIP_VERSION_CHECK=ON nice -n 10 .venv/bin/python benchmarks/bench_sfm.py \
        --accuracy-seeds 1 2 3 --work /tmp/bench_sfm_acc
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

    from scenebot.capture.stage import run_capture
    from scenebot.config import validate_config

    data = yaml.safe_load(config.read_text())
    for r, n in ((0, photos0), (1, photos1)):
        cap = scene / f"round_{r:03d}" / "capture"
        if (cap / "log.jsonl").exists():
            continue
        data.setdefault("exploration", {})["photos"] = n
        data["seed"] = int(data.get("seed", 1)) + r  # another random walk in round 1
        run_capture(validate_config(data), cap, r, progress=False)


def camera_offset_from_config(config: Path) -> float:
    """The simulated camera's distance from the rotation axis (m), as the robot's mount."""
    import math

    import yaml

    from scenebot.config import validate_config

    cam = validate_config(yaml.safe_load(config.read_text())).sim.camera
    return math.hypot(cam.forward_offset_m, cam.lateral_offset_m)


def camera_offset_from_log(log_path: Path) -> float:
    """The camera mount's distance from the rotation axis (m) from the capture log's session
    record (the simulator's camera config); 0.10 m (the synthetic room's) when absent."""
    import math

    first = json.loads(log_path.read_text().splitlines()[0])
    cam = first.get("config", {}).get("sim", {}).get("camera", {})
    if "forward_offset_m" not in cam:
        return 0.10
    return math.hypot(cam["forward_offset_m"], cam.get("lateral_offset_m", 0.0))


def accuracy_by_seed(seeds: list[int], config: Path, work: Path, photos: int) -> int:
    """Round-0 accuracy per exploration seed: default settings vs the previous defaults."""
    import yaml

    from scenebot.capture.stage import run_capture
    from scenebot.config import validate_config

    offset = camera_offset_from_config(config)
    variants = {
        "reference": SfmConfig(plots=False, fix_exif_focal=False),
        "default": SfmConfig(plots=False, camera_offset_m=offset),
    }
    rows = []
    for seed in seeds:
        scene = work / f"seed{seed}"
        cap = scene / "round_000" / "capture"
        if not (cap / "log.jsonl").exists():
            data = yaml.safe_load(config.read_text())
            data["seed"] = seed
            data.setdefault("exploration", {})["photos"] = photos
            run_capture(validate_config(data), cap, 0, progress=False)
        for name, cfg in variants.items():
            out = SfmOutputs(scene / f"sfm_{name}")
            s, rep = timed_run(cfg, SfmInputs(scene / "sfm_db" / "database.db", [cap]), out)
            rows.append((seed, name, s, rep))
    print(f"sfm accuracy by seed: {photos} photos, camera offset {offset:.3f} m, "
          f"cores={os.cpu_count()} (time: the first variant of a seed includes extraction "
          "and matching)")  # fmt: skip
    print(f"{'seed':<6}{'settings':<11}{'s':>7}{'registered':>12}{'pos med cm':>12}"
          f"{'pos p90 cm':>12}{'heading deg':>13}{'scale err %':>13}  scale source "
          "(odometry vs lever arm %)")  # fmt: skip
    for seed, name, s, rep in rows:
        acc, sc = rep["accuracy"], rep["scale"]
        diff = sc.get("odometry_vs_lever_arm")
        print(
            f"{seed:<6}{name:<11}{s:>7.0f}{rep['registered']:>7}/{rep['photos']:<4}"
            f"{acc['position_error_m']['median'] * 100:>12.2f}"
            f"{acc['position_error_m']['p90'] * 100:>12.2f}"
            f"{acc['heading_error_deg']['median']:>13.3f}"
            f"{acc['metric_scale_error'] * 100:>13.2f}  {sc['source']}"
            + (f" ({diff * 100:+.1f})" if diff is not None else "")
        )
    return 0


def make_synthetic_rounds(scene: Path) -> None:
    from scenebot.testing.sfm import SyntheticRoom, make_capture

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
    ap.add_argument("--accuracy-seeds", type=int, nargs="*", help="round-0 accuracy per seed")
    ap.add_argument("--photos", type=int, default=100, help="round-0 photos (accuracy mode)")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    work = Path(args.work)
    if args.accuracy_seeds:
        return accuracy_by_seed(args.accuracy_seeds, Path(args.config), work, args.photos)
    scene = Path(args.scene) if args.scene else work / "scene"
    if not args.scene:
        if args.source == "sim":
            make_sim_rounds(scene, Path(args.config), args.photos0, args.photos1)
        else:
            make_synthetic_rounds(scene)
    caps = [scene / "round_000/capture", scene / "round_001/capture"]
    offset = camera_offset_from_log(caps[0] / "log.jsonl")
    cfg = SfmConfig(plots=False, camera_offset_m=offset)
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
