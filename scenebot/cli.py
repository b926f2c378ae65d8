"""The ``scenebot`` command line: every stage callable outside Snakemake.

Examples::

    scenebot capture --config config.yaml --out results/office/round_000/capture
    scenebot schema --write
    scenebot check-config config.yaml
    scenebot rooms-gallery --seeds 1-8 --out rooms.png
    scenebot guide serve --host 0.0.0.0
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import sys
from pathlib import Path

from scenebot.config import ConfigError, from_sections, load_config


def _config(args) -> object:
    if getattr(args, "params", None):
        return from_sections(args.params)
    return load_config(args.config)


def cmd_capture(args) -> int:
    from scenebot.capture.stage import run_capture

    cfg = _config(args)
    if cfg.guided_rounds():  # a person's round: the folder, the walk, or the inbox
        from scenebot.capture import person

        if args.round > 0:
            summary = person.run_inbox_round(cfg, Path(args.out), args.round)
        elif cfg.robot == "guided":
            summary = person.run_folder_round(cfg, Path(args.out))
        else:
            summary = person.run_perimeter_round(cfg, Path(args.out))
        print(json.dumps(summary, default=str))
        return 0
    if args.round > 0:
        from scenebot.capture.adaptive import run_adaptive

        if not args.previous:
            raise ValueError("capture --round >= 1 needs --previous results/<scene>/round_XXX")
        summary = run_adaptive(
            cfg, Path(args.out), args.round, Path(args.previous), progress=not args.no_progress
        )
        print(json.dumps(summary))
        return 0
    summary = run_capture(cfg, Path(args.out), args.round, progress=not args.no_progress)
    print(json.dumps(summary))
    return 0


# The files each stage reads and writes, one option per field of its inputs and outputs
# dataclasses (``sfm_dir`` -> ``--sfm-dir``; ``?`` optional, ``*`` a list): the rule names every
# file. Written here rather than read from the dataclasses, so that building the parser imports
# no stage (tests/test_cli.py checks that the two agree).
STAGE_FILES = {
    "sfm": ("database", "capture_dirs*", "photo_folder?", "previous_model?", "shots_json?",
            "model_dir"),
    "mesh": ("sfm_dir", "mesh_ply", "freespace_json", "freespace_npz", "freespace_png?"),
    "score": ("sfm_dir", "mesh_ply", "freespace_npz", "candidates_csv", "views_png?"),
    "goals": ("candidates_csv", "freespace_npz", "sfm_dir?", "previous_goals_json?",
              "previous_freespace_npz?", "mesh_ply?", "capture_logs*", "fulfilment_json?",
              "goals_json", "goals_png?"),
    "plan": ("sfm_dir", "goals_json", "navgrid_npz", "paths_json", "plot_png?"),
    "goals-preview": ("sfm_dir", "image_dir", "goals_json", "preview_png", "preview_npz?"),
    "guide-page": ("sfm_dir", "image_dir", "goals_json", "preview_npz", "coverage_png",
                   "guide_html"),
    "guide-fulfilment": ("sfm_dir", "previous_sfm_dir", "goals_json", "capture_log",
                         "sfm_report", "previous_fulfilment_json?", "fulfilment_json"),
    "suite-report": ("evaluations*", "baselines*", "suite_json", "suite_md", "suite_png"),
}  # fmt: skip


def add_files(parser: argparse.ArgumentParser, names: tuple[str, ...]) -> None:
    """The options of a stage's files (:data:`STAGE_FILES`)."""
    for name in names:
        field = name.rstrip("?*")
        parser.add_argument(
            "--" + field.replace("_", "-"),
            dest=field,
            type=Path,
            required=not name.endswith(("?", "*")),
            nargs="*" if name.endswith("*") else None,
            metavar="PATH",
        )


def files(args, cls: type):
    """A stage's inputs or outputs dataclass from the options :func:`add_files` made."""
    given = {f.name: getattr(args, f.name) for f in dataclasses.fields(cls)}
    return cls(**{k: v for k, v in given.items() if v is not None})


def cmd_sfm(args) -> int:
    from scenebot.sfm.stage import SfmInputs, SfmOutputs, run

    cfg, inputs = _config(args), files(args, SfmInputs)
    prev = inputs.previous_model  # round r-1's map, when it holds one
    if prev is not None and not (prev / "images.bin").exists():
        inputs.previous_model = None
    out = run(cfg.sfm, inputs, files(args, SfmOutputs), person=cfg.person_photos())
    print(json.dumps(out, default=str)[:2000])
    return 0


def cmd_mesh(args) -> int:
    from scenebot.mesh.stage import MeshInputs, MeshOutputs, run

    cfg = _config(args)
    person = cfg.person_photos()  # a person's photos: six degrees of freedom
    summary = run(cfg.mesh, files(args, MeshInputs), files(args, MeshOutputs), person=person)
    print(json.dumps(summary, default=str))
    return 0


def cmd_score(args) -> int:
    from scenebot.score.stage import ScoreInputs, ScoreOutputs, run

    cfg = _config(args)
    person = cfg.person_photos()
    summary = run(cfg.score, files(args, ScoreInputs), files(args, ScoreOutputs), person=person)
    print(json.dumps(summary, default=str))
    return 0


def cmd_goals(args) -> int:
    from scenebot.goals.stage import GoalsInputs, GoalsOutputs, run

    cfg = _config(args)
    person = cfg.person_photos()
    doc = run(cfg.goals, files(args, GoalsInputs), files(args, GoalsOutputs), person=person)
    print(json.dumps(doc))
    return 0


def cmd_goals_preview(args) -> int:
    from scenebot.goals.preview import PreviewInputs, PreviewOutputs, run

    cfg = _config(args)
    summary = run(cfg.goals, cfg.tour, files(args, PreviewInputs), files(args, PreviewOutputs))
    print(json.dumps(summary))
    return 0


def cmd_guide_page(args) -> int:
    from scenebot.guide.page import GuideInputs, GuideOutputs, run

    cfg = _config(args)
    print(json.dumps(run(cfg.guide, files(args, GuideInputs), files(args, GuideOutputs))))
    return 0


def cmd_guide_serve(args) -> int:
    from scenebot.guide.serve import serve

    cfg = _config(args)
    guide = cfg.guide.model_copy(update={k: v for k, v in (("host", args.host),
                                 ("port", args.port)) if v is not None})  # fmt: skip
    scene_dir = Path(args.scene_dir) if args.scene_dir else Path("results") / cfg.scene
    serve(guide, scene_dir, round_=args.round)
    return 0


def cmd_guide_skip(args) -> int:
    from scenebot.artifacts import inbox_dir
    from scenebot.artifacts.skipped import write_skipped
    from scenebot.guide.serve import check_shots, current_round

    cfg = _config(args)
    scene_dir = Path(args.scene_dir) if args.scene_dir else Path("results") / cfg.scene
    rnd = current_round(scene_dir, args.round)
    check_shots(scene_dir, rnd, sorted(set(args.shots)))
    path = write_skipped(inbox_dir(scene_dir, rnd), {k: args.reason for k in args.shots})
    print(f"{path}: shots {', '.join(map(str, sorted(args.shots)))} of round {rnd}'s guide "
          "marked as not taken; run snakemake: the next guide asks for others")  # fmt: skip
    return 0


def cmd_person_sim(args) -> int:
    from scenebot.capture.person import run_person_sim_shots

    cfg = _config(args)
    if cfg.robot != "person-sim":
        raise ValueError(f"person-sim runs for robot: person-sim, not robot: {cfg.robot}")
    print(json.dumps(run_person_sim_shots(cfg, Path(args.scene_dir), args.round), default=str))
    return 0


def cmd_guide_fulfilment(args) -> int:
    from scenebot.guide.fulfil import FulfilInputs, FulfilOutputs, run

    cfg = _config(args)
    doc = run(cfg.guide, files(args, FulfilInputs), files(args, FulfilOutputs))
    print(json.dumps(doc["summary"], default=str))
    return 0


def cmd_plan(args) -> int:
    from scenebot.plan.stage import PlanInputs, PlanOutputs, run

    cfg = _config(args)
    doc = run(cfg.plan, files(args, PlanInputs), files(args, PlanOutputs),
              camera_offset_m=cfg.camera_mount())  # fmt: skip
    print(json.dumps(doc, default=str)[:2000])
    return 0


def cmd_dense(args) -> int:
    from scenebot.dense.stage import DenseInputs, DenseOutputs, run

    cfg = _config(args)
    inputs = DenseInputs(Path(args.sparse), Path(args.images))
    print(json.dumps(run(cfg.dense, inputs, DenseOutputs(Path(args.out))), default=str))
    return 0


def cmd_tour(args) -> int:
    from scenebot.tour.stage import TourInputs, TourOutputs, run

    cfg = _config(args)
    photos = cfg.person_photos()  # a person's photos: no free space, no metric scale
    inputs = TourInputs(
        Path(args.sparse),
        Path(args.images),
        Path(args.dense),
        Path(args.freespace) if args.freespace and not photos else None,
        photos=photos,
    )
    summary = run(cfg.tour, inputs, TourOutputs(Path(args.out)), progress=not args.no_progress)
    summary.pop("config", None)
    print(json.dumps(summary, default=str)[:2000])
    return 0


def cmd_proxy(args) -> int:
    import time

    from scenebot.tour.proxy import load_proxy, save_proxy

    cfg = _config(args)
    t0 = time.perf_counter()
    proxy = load_proxy(Path(args.dense), cfg.tour.proxy)
    out = save_proxy(proxy, Path(args.out), cfg.tour.proxy, source=args.dense)
    print(json.dumps({"proxy": str(out), "points": len(proxy),
                      "seconds": round(time.perf_counter() - t0, 1)}))  # fmt: skip
    return 0


def cmd_campaign(args) -> int:
    from scenebot.campaign import write

    cfg = _config(args)
    rounds = [int(r) for r in args.rounds.split(",")]
    summary = write(Path(args.scene_dir), rounds, cfg.round_limit(), Path(args.out))
    print(json.dumps({k: summary[k] for k in ("photos_total", "stopped_because")}))
    return 0


def cmd_timing(args) -> int:
    from scenebot.timing import write

    doc = write(Path(args.benchmarks), Path(args.out), Path(args.png) if args.png else None)
    print(json.dumps({k: doc[k] for k in ("jobs_seconds", "jobs_cpu_seconds", "cpu_per_wall")}))
    return 0


def cmd_suite_report(args) -> int:
    from scenebot.evaluate.suite import SuiteInputs, SuiteOutputs, run

    summary = run(args.names, files(args, SuiteInputs), files(args, SuiteOutputs))
    print(json.dumps(summary, default=str))
    return 0


def cmd_nxt_emulator(args) -> int:
    from scenebot.robot.factory import make_emulator_world
    from scenebot.robot.nxt.backend import serve_emulator

    cfg = _config(args)
    inbox = Path(args.inbox) if args.inbox else None
    serve_emulator(make_emulator_world(cfg), cfg.nxt, cfg.nxt_emulator, inbox=inbox)
    return 0


def cmd_schema(args) -> int:
    from scenebot.config import json_schema, write_schema

    if args.write:
        print(write_schema())
    else:
        print(json.dumps(json_schema(), indent=2, sort_keys=True))
    return 0


def cmd_check_config(args) -> int:
    # the workflow's own check: typed model and JSON schema (rules/common.smk)
    cfg = load_config(args.path)
    print(f"{args.path}: valid (scene {cfg.scene!r}, robot {cfg.robot!r})")
    return 0


def cmd_rooms_gallery(args) -> int:
    from scenebot.scene.gallery import draw_rooms, parse_seeds
    from scenebot.scene.rooms import describe

    seeds = parse_seeds(args.seeds)
    print(draw_rooms(seeds, Path(args.out)))
    for seed in seeds:
        print(json.dumps(describe(seed)))
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="scenebot", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)

    def with_config(sp):
        sp.add_argument("--config", default="config.yaml", help="campaign config (YAML)")
        sp.add_argument("--params", help="stage parameters as JSON (used by the workflow)")

    c = sub.add_parser(
        "capture", help="capture: random exploration (round 0), goals of the last map (r >= 1)"
    )
    with_config(c)
    c.add_argument("--out", required=True, help="capture folder (round_XXX/capture)")
    c.add_argument("--round", type=int, default=0)
    c.add_argument("--previous", help="rounds >= 1: the previous round's folder (round_XXX)")
    c.add_argument("--no-progress", action="store_true")
    c.set_defaults(func=cmd_capture)

    for name, func, text in (
        ("sfm", cmd_sfm, "structure from motion of rounds 0..r (robot frame)"),
        ("mesh", cmd_mesh, "Poisson mesh and free space of a round's map"),
        ("score", cmd_score, "random candidates scored by the rendering-quality heuristic"),
        ("goals", cmd_goals, "the best goals; whether exploration is complete"),
        ("plan", cmd_plan, "navigation grid and paths to the goals"),
        ("goals-preview", cmd_goals_preview, "a person's advised shots rendered from the photos"),
    ):
        sp = sub.add_parser(name, help=text)
        with_config(sp)
        add_files(sp, STAGE_FILES[name])
        sp.set_defaults(func=func)

    gd = sub.add_parser("guide", help="a person's guide: the next shots on a page, on a phone")
    gsub = gd.add_subparsers(dest="guide_command", required=True)
    gp = gsub.add_parser("page", help="write a round's guide page (round_XXX/guide/index.html)")
    with_config(gp)
    add_files(gp, STAGE_FILES["guide-page"])
    gp.set_defaults(func=cmd_guide_page)
    gf = gsub.add_parser(
        "fulfilment",
        help="which shots of the previous round's guide each photo of a round fulfilled "
        "(round_XXX/fulfilment.json)",
    )
    with_config(gf)
    add_files(gf, STAGE_FILES["guide-fulfilment"])
    gf.set_defaults(func=cmd_guide_fulfilment)
    ps = sub.add_parser(
        "person-sim",
        help="robot: person-sim: the simulated person takes the shots of round r-1's guide "
        "into round r's inbox",
    )
    with_config(ps)
    ps.add_argument("--scene-dir", required=True, help="results/<scene>")
    ps.add_argument("--round", type=int, required=True, help="the round whose inbox it fills")
    ps.set_defaults(func=cmd_person_sim)
    gs = gsub.add_parser(
        "serve",
        help="serve the current round's guide to a phone and take its photos into the next "
        "round's inbox (round_XXX/capture/inbox)",
    )
    with_config(gs)
    gs.add_argument("--scene-dir", help="the campaign's folder (default results/<scene>)")
    gs.add_argument("--round", type=int, help="the guide of this round (default: the latest)")
    gs.add_argument("--host", help="address to listen on (default guide.host, 127.0.0.1: this "
                    "computer only; 0.0.0.0: a phone on the same network too)")  # fmt: skip
    gs.add_argument("--port", type=int, help="port (default guide.port)")
    gs.set_defaults(func=cmd_guide_serve)
    gk = gsub.add_parser(
        "skip",
        help="mark shots of the current guide that you cannot take (behind a wall, out of "
        "reach): the next round plans others, also when you took no photo",
    )
    with_config(gk)
    gk.add_argument("shots", type=int, nargs="+", help="shot numbers as on the guide page")
    gk.add_argument("--scene-dir", help="the campaign's folder (default results/<scene>)")
    gk.add_argument("--round", type=int, help="the guide of this round (default: the latest)")
    gk.add_argument("--reason", default="the person could not take it", help="why (kept in "
                    "the round's capture log and fulfilment.json)")  # fmt: skip
    gk.set_defaults(func=cmd_guide_skip)

    d = sub.add_parser("dense", help="dense multi-view stereo and fusion of a map")
    with_config(d)
    d.add_argument("--sparse", required=True, help="COLMAP model folder (round_XXX/sfm)")
    d.add_argument("--images", required=True, help="folder the model's image names live in")
    d.add_argument("--out", required=True, help="dense workspace (final/dense)")
    d.set_defaults(func=cmd_dense)

    pr = sub.add_parser(
        "proxy", help="the dense cloud prepared for rendering (the tour's and validity's proxy)"
    )
    with_config(pr)
    pr.add_argument("--dense", required=True, help="dense cloud (final/dense/fused.ply)")
    pr.add_argument("--out", required=True, help="prepared proxy (final/tour/proxy.npz)")
    pr.set_defaults(func=cmd_proxy)

    t = sub.add_parser("tour", help="virtual tour: ULR frames, tour.mp4, web viewer")
    with_config(t)
    t.add_argument("--sparse", required=True, help="COLMAP model folder (round_XXX/sfm)")
    t.add_argument("--images", required=True, help="folder the model's image names live in")
    t.add_argument(
        "--dense",
        required=True,
        help="the proxy (final/tour/proxy.npz), or a dense cloud (final/dense/fused.ply) to "
        "build it from",
    )
    t.add_argument("--freespace", help="free space of the map (round_XXX/freespace.npz)")
    t.add_argument("--out", required=True, help="tour folder (final/tour)")
    t.add_argument("--no-progress", action="store_true")
    t.set_defaults(func=cmd_tour)

    from scenebot.evaluate.cli import add_parsers

    add_parsers(sub)  # observable, evaluate, validity

    cp = sub.add_parser("campaign", help="campaign.json: photos, registered, scores per round")
    with_config(cp)
    cp.add_argument("--scene-dir", required=True, help="results/<scene>")
    cp.add_argument("--rounds", required=True, help="the rounds run, e.g. 0,1,2")
    cp.add_argument("--out", required=True, help="results/<scene>/campaign.json")
    cp.set_defaults(func=cmd_campaign)

    su = sub.add_parser(
        "suite-report",
        help="the scene suite's table: per scene (in --names order) its final evaluation "
        "and baselines; the median and the worst scene",
    )
    su.add_argument("--names", nargs="+", required=True, metavar="SCENE", help="the scenes")
    add_files(su, STAGE_FILES["suite-report"])
    su.set_defaults(func=cmd_suite_report)

    tm = sub.add_parser("timing", help="where a campaign's time went (Snakemake's benchmarks)")
    tm.add_argument("--benchmarks", required=True, help="results/<scene>/benchmarks")
    tm.add_argument("--out", required=True, help="results/<scene>/timing.json")
    tm.add_argument("--png", help="results/<scene>/timing.png")
    tm.set_defaults(func=cmd_timing)

    e = sub.add_parser(
        "nxt-emulator",
        help="serve the NXT brick emulator on a pseudo-terminal (prints the port to use)",
    )
    with_config(e)
    e.add_argument("--inbox", help="folder the emulated Wi-Fi card writes photos to")
    e.set_defaults(func=cmd_nxt_emulator)

    s = sub.add_parser("schema", help="print (or --write) the config JSON schema")
    s.add_argument("--write", action="store_true")
    s.set_defaults(func=cmd_schema)

    k = sub.add_parser("check-config", help="validate a config file")
    k.add_argument("path")
    k.set_defaults(func=cmd_check_config)

    g = sub.add_parser(
        "rooms-gallery", help="plan views of the generated rooms (world.builtin: rooms), per seed"
    )
    g.add_argument("--seeds", default="1-8", help="seeds, e.g. 1-8 or 1,3,10-12")
    g.add_argument("--out", required=True, help="the PNG to write")
    g.set_defaults(func=cmd_rooms_gallery)
    return p


def main(argv: list[str] | None = None) -> int:
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except (FileNotFoundError, ValueError, RuntimeError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
