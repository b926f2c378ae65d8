"""Benchmark of an adaptive round's sfm on a finished campaign's own photos, setting by setting.

For each chosen round r of a campaign (``results/{scene}``), every variant runs the sfm
stage as the campaign's round r did: the same capture folders of rounds 0..r, continued from
the campaign's own round r-1 map (round 0: from scratch), on a copy of the campaign's
database cut back to what it held before round r (the photos of rounds r and later, their
keypoints, descriptors, frames and every pair that involves them removed), so that each
variant extracts and matches round r's new photos itself. The variants differ only in sfm
settings (``--variant name:key=value,key=value``; ``default`` is the config's own; the key
``loops=whole_set`` selects the loop-closure pairs as before 2026-11-26, spread over the
whole set, whose partners moved each round: the same-run reference of the stable ones).
Rows: wall seconds (median of ``--repeats``), the stage's own timings, photos registered,
the camera error against the simulator's truth (the stage's ``accuracy.json``; evaluation
only).

    TI_SKIP_VERSION_CHECK=ON .venv/bin/python benchmarks/bench_sfm_rounds.py \\
        --campaign results/office --rounds 1 3 5 \\
        --variant default --variant register:register_new_photos=true --work /tmp/sfmr

The cut keeps every pair among earlier photos that the database holds: a campaign made with
the loop pairs before 2026-11-26 (spread over the whole set, moving each round) also holds the
pairs among old photos that later rounds matched, so this under-counts what those rounds
matched (their own ``report.json`` says it: ``pairs.matched_now``).

The variants of one round run interleaved (all variants, then all again), so the machine's
load falls on them alike; the table states the load beside each row.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sqlite3
import statistics
import time
from pathlib import Path

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")

from scenebot.config import load_config
from scenebot.sfm import pairs, stage
from scenebot.sfm.config import SfmConfig
from scenebot.sfm.stage import SfmInputs, SfmOutputs, run

PAIR_ID_BASE = 2147483647  # COLMAP's pair_id = id1 * 2147483647 + id2 (id1 < id2)


def round_of(name: str) -> int:
    """Capture round of a photo name such as ``round_003/capture/images/r003_0012.jpg``."""
    return int(name.split("/")[0].split("_")[1])


def cut_database(src: Path, dst: Path, before_round: int) -> int:
    """Copy the database ``src`` to ``dst`` without the photos of rounds >= ``before_round``
    (their rows in every table, and every pair that involves one); the photos sidecar too.

    Returns:
        The photos kept.
    """
    dst.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(src, dst)
    con = sqlite3.connect(dst)
    rows = con.execute("SELECT image_id, name FROM images").fetchall()
    gone = [i for i, n in rows if round_of(n) >= before_round]
    con.execute("CREATE TEMP TABLE gone (id INTEGER PRIMARY KEY)")
    con.executemany("INSERT INTO gone VALUES (?)", [(i,) for i in gone])
    for table in ("keypoints", "descriptors", "images"):
        con.execute(f"DELETE FROM {table} WHERE image_id IN (SELECT id FROM gone)")
    frames = "SELECT frame_id FROM frame_data WHERE data_id IN (SELECT id FROM gone)"
    con.execute(f"DELETE FROM frames WHERE frame_id IN ({frames})")
    con.execute("DELETE FROM frame_data WHERE data_id IN (SELECT id FROM gone)")
    for table in ("matches", "two_view_geometries"):
        con.execute(
            f"DELETE FROM {table} WHERE pair_id / {PAIR_ID_BASE} IN (SELECT id FROM gone) "
            f"OR pair_id % {PAIR_ID_BASE} IN (SELECT id FROM gone)"
        )
    con.commit()
    con.execute("VACUUM")
    con.close()
    side_src = src.with_name(src.name + ".photos.json")
    if side_src.exists():
        side = json.loads(side_src.read_text())
        kept = {n: h for n, h in side.items() if round_of(n) < before_round}
        dst.with_name(dst.name + ".photos.json").write_text(json.dumps(kept, indent=1))
    return len(rows) - len(gone)


def parse_variant(text: str) -> tuple[str, dict]:
    """``name`` or ``name:key=value,key=value`` (values parsed as JSON where they can be)."""
    name, _, rest = text.partition(":")
    changes: dict = {}
    for item in filter(None, rest.split(",")):
        key, _, value = item.partition("=")
        try:
            changes[key] = json.loads(value)
        except json.JSONDecodeError:
            changes[key] = value
    return name, changes


def whole_set_loops(select_pairs):
    """``select_pairs`` with the loop-closure pairs of the rule before: each photo's
    ``loop_closure_pairs`` partners spread over the whole set (they move as photos are added)."""

    def select(priors, **kw):
        out = select_pairs(priors, **kw)
        n, k_max = len(priors), kw["loop_closure_pairs"]
        loops = set()
        if n > kw["exhaustive_max_images"]:
            for i in range(n):
                for k in range(1, k_max + 1):
                    j = (i + (k * n) // (k_max + 1)) % n
                    if i != j:
                        a, b = priors[i].name, priors[j].name
                        loops.add((a, b) if a < b else (b, a))
        out["loop"] = loops
        return out

    return select


def one_run(cfg: SfmConfig, campaign: Path, r: int, work: Path, guided: bool = False) -> dict:
    """The sfm stage of round r on a cut copy of the campaign's database; its figures.
    ``guided``: a person's campaign (robot: guided, person-sim): the person's map check,
    and the previous round's shots."""
    shutil.rmtree(work, ignore_errors=True)
    db = work / "database.db"
    kept = cut_database(campaign / "sfm_db" / "database.db", db, r)
    captures = [campaign / f"round_{k:03d}" / "capture" for k in range(r + 1)]
    previous = campaign / f"round_{r - 1:03d}" / "sfm" if r > 0 else None  # round 0: scratch
    shots = campaign / f"round_{r - 1:03d}" / "goals.json" if guided and r > 0 else None
    inputs = SfmInputs(
        database=db, capture_dirs=captures, previous_model=previous, shots_json=shots
    )
    load = os.getloadavg()[0]
    t = time.perf_counter()
    report = run(cfg, inputs, SfmOutputs(model_dir=work / "model"), person=guided)
    wall = time.perf_counter() - t
    acc = report.get("accuracy") or {}
    return {
        "wall_s": wall,
        "load": load,
        "photos_in_db_before": kept,
        "photos": report["photos"],
        "registered": report["registered"],
        "new_pairs": report["pairs"].get("matched_now"),
        "timings_s": report["timings_s"],
        "global_refinement": report.get("global_refinement"),
        "accuracy": acc,
        "gross_errors": _gross(work),
    }


def _error_cm(acc: dict, key: str) -> float:
    v = (acc.get("position_error_m") or {}).get(key)
    return float("nan") if v is None else 100.0 * float(v)


def _gross(work: Path) -> int:
    """Photos registered > 25 cm from the truth (the stage's accuracy.json)."""
    path = work / "model" / "accuracy.json"
    if not path.exists():
        return -1
    return int(json.loads(path.read_text()).get("gross_errors", {}).get("count", 0))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--campaign", type=Path, required=True, help="results/{scene} of a campaign")
    ap.add_argument("--config", type=Path, default=Path("config.yaml"))
    ap.add_argument("--rounds", type=int, nargs="+", required=True)
    ap.add_argument("--variant", action="append", default=[], help="name[:key=value,...]")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--work", type=Path, default=Path("/tmp/bench_sfm_rounds"))
    ap.add_argument("--json", type=Path, help="write every run's figures here")
    args = ap.parse_args(argv)

    config = load_config(args.config)
    base, guided = config.sfm, config.guided_rounds()
    variants = [parse_variant(v) for v in (args.variant or ["default"])]
    results: dict[str, dict[int, list[dict]]] = {name: {} for name, _ in variants}
    for r in args.rounds:
        for rep in range(args.repeats):
            for name, changes in variants:
                changes = dict(changes)
                loops = changes.pop("loops", "stable")
                stage.select_pairs = (
                    whole_set_loops(pairs.select_pairs)
                    if loops == "whole_set"
                    else pairs.select_pairs
                )
                cfg = SfmConfig.model_validate({**base.model_dump(), **changes})
                res = one_run(cfg, args.campaign, r, args.work / f"r{r}" / name, guided)
                results[name].setdefault(r, []).append(res)
                print(f"round {r} {name} repeat {rep}: {res['wall_s']:.1f} s", flush=True)

    print(
        "\n| round | variant | wall s (median) | load | map s | match s | registered | "
        "median / p90 camera error (cm) | > 25 cm | global refinement |"
    )
    print("|---|---|---:|---:|---:|---:|---|---|---:|---|")
    for r in args.rounds:
        for name, _ in variants:
            runs = results[name][r]
            med = statistics.median(x["wall_s"] for x in runs)
            x = runs[0]
            acc = x["accuracy"]
            glob = x["global_refinement"] or {}
            print(
                f"| {r} | {name} | {med:.1f} | {statistics.median(y['load'] for y in runs):.1f} "
                f"| {x['timings_s'].get('map', 0):.1f} | {x['timings_s'].get('match', 0):.1f} "
                f"| {x['registered']}/{x['photos']} "
                f"| {_error_cm(acc, 'median'):.2f} / {_error_cm(acc, 'p90'):.2f} "
                f"| {x['gross_errors']} "
                f"| {glob.get('run', '-')} |"
            )
    if args.json:
        args.json.write_text(json.dumps(results, indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
