"""Command line of the evaluation: ``python -m scenebot.evaluate {observable,evaluate} ...``.

Meant to be merged into ``scenebot`` 's CLI (:func:`add_parsers`); until then it runs on its
own. ``--params`` takes the workflow's stage parameters (``section_json`` of the campaign
config), optionally with an ``evaluate`` section; ``--config`` a campaign YAML file.

Examples::

    python -m scenebot.evaluate observable --config config.yaml \\
        --out results/office/eval/observable_surface.npz
    python -m scenebot.evaluate evaluate --config config.yaml --scene-dir results/office \\
        --round 0 --dense results/office/final/dense/fused.ply
    python -m scenebot.evaluate baselines --replot-only --config config.yaml \\
        --scene-dir results/office --out results/office/baselines/baselines.json
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from scenebot.evaluate.config import EvaluateConfig


def load_settings(args) -> tuple[object, EvaluateConfig]:
    """(campaign Config, EvaluateConfig) from ``--params`` JSON or ``--config`` YAML."""
    import yaml

    from scenebot.config import ConfigError, validate_config

    if getattr(args, "params", None):
        data, source = json.loads(args.params), "stage parameters"
    else:
        path = Path(args.config)
        if not path.is_file():
            raise ConfigError(
                f"config file {path} not found (copy config.yaml from the repository)"
            )
        data, source = yaml.safe_load(path.read_text()) or {}, str(path)
    ev = data.pop("evaluate", None) or {}
    # stage parameters hold only the stage's sections: checks across others do not apply
    cfg = validate_config(data, source, sections=data if source == "stage parameters" else None)
    got = getattr(cfg, "evaluate", None)  # once the lead merges the section into Config
    ecfg = got if isinstance(got, EvaluateConfig) and not ev else EvaluateConfig(**ev)
    return cfg, ecfg


def cmd_observable(args) -> int:
    from scenebot.evaluate.stage import ObservableOutputs, run_observable

    cfg, ecfg = load_settings(args)
    if args.cache_dir is not None:  # the workflow's evaluate.cache_dir (not in --params)
        ecfg.cache_dir = args.cache_dir
    out = Path(args.out)
    png = Path(args.png) if args.png else out.with_suffix(".png")
    print(json.dumps(run_observable(cfg, ObservableOutputs(out, png), ecfg), default=str))
    return 0


def cmd_evaluate(args) -> int:
    from scenebot.evaluate.stage import EvaluateInputs, EvaluateOutputs, main_summary, run

    cfg, ecfg = load_settings(args)
    scene_dir = Path(args.scene_dir)
    rdir = scene_dir / f"round_{args.round:03d}"
    caps = [scene_dir / f"round_{k:03d}" / "capture" for k in range(args.round + 1)]
    if cfg.robot == "photos":  # round 0 is a folder of photos: its truth, if any, is given
        caps = [c for c in caps if (c / "log.jsonl").is_file()]
        if args.reference:
            caps = [Path(args.reference), *caps]
    inputs = EvaluateInputs(
        sfm_dir=rdir / "sfm",
        captures=caps,
        dense_cloud=Path(args.dense) if args.dense else None,
        observable=Path(args.observable)
        if args.observable
        else scene_dir / "eval" / "observable_surface.npz",
        round_index=args.round,
    )
    out = Path(args.out) if args.out else rdir / "evaluation.json"
    ev = run(cfg, inputs, EvaluateOutputs(out, out.with_suffix(".png")), ecfg)
    print(main_summary(ev))
    return 0


def cmd_reference(args) -> int:
    from scenebot.evaluate.reference import read_reference_cameras, write_reference_log

    _, ecfg = load_settings(args)
    if ecfg.reference_cameras is None:
        raise SystemExit("evaluate.reference_cameras is not set: no reference cameras to write")
    n = write_reference_log(read_reference_cameras(ecfg.reference_cameras), Path(args.out))
    print(json.dumps({"reference_cameras": str(ecfg.reference_cameras), "cameras": n}))
    return 0


def cmd_validity(args) -> int:
    from scenebot.evaluate.validity import ValidityInputs, run_validity

    cfg, ecfg = load_settings(args)
    cfg.evaluate = ecfg
    scene_dir = Path(args.scene_dir)
    r = ecfg.validity_round if args.round is None else args.round
    if r > args.dense_round:
        raise ValueError(
            f"score validity of round {r}: the campaign's dense cloud comes from round "
            f"{args.dense_round}, before it; set evaluate.validity_round <= {args.dense_round}"
        )
    rdir = scene_dir / f"round_{r:03d}"
    inputs = ValidityInputs(
        round_dir=rdir,
        image_dir=scene_dir,
        captures=[scene_dir / f"round_{k:03d}" / "capture" for k in range(r + 1)],
        dense_ply=Path(args.dense),
        dense_sfm_dir=scene_dir / f"round_{args.dense_round:03d}" / "sfm",
    )
    out = Path(args.out)
    s = run_validity(cfg, inputs, out, out.with_suffix(".png"))
    lo, hi = s["spearman_95ci"]
    print(
        f"score validity ({s['round']}, {s['candidates']} views): Spearman(score, PSNR) = "
        f"{s['spearman_score_psnr']:.3f} [95% {lo:.3f}, {hi:.3f}], median PSNR "
        f"{s['psnr_db']['median']:.1f} dB, {s['seconds']:.0f} s"
    )
    return 0


def cmd_baselines(args) -> int:
    import yaml

    from scenebot.evaluate.baselines import refresh_baselines, run_baselines

    if args.campaign:
        campaign = json.loads(args.campaign)
    else:
        path = Path(args.config)
        if not path.is_file():
            raise FileNotFoundError(f"campaign config {path} not found (or give --campaign)")
        campaign = yaml.safe_load(path.read_text()) or {}
    methods = tuple(m for m in args.methods.split(",") if m)
    if args.replot_only:
        s = refresh_baselines(campaign, Path(args.scene_dir), Path(args.out), methods)
    else:
        s = run_baselines(campaign, Path(args.scene_dir), Path(args.out), methods, args.cores)
    for name, v in s.items():
        if isinstance(v, dict) and v.get("dense"):
            d = v["dense"].get("2cm", {})
            print(f"{name}: {v['photos']} photos, completeness at 2 cm "
                  f"{100 * d.get('completeness', float('nan')):.1f}%, accuracy "
                  f"{100 * d.get('accuracy', float('nan')):.1f}%")  # fmt: skip
            cov = v.get("coverage_by_photos") or {}
            pts = zip(cov.get("photos", []), cov.get("seen_2", []), strict=True)
            at = [f"{n}: {100 * c:.1f}" for n, c in pts if n % 25 == 0 or n == cov["photos"][-1]]
            if at:
                print("  % of the observable area seen by >= 2 photos after n photos: "
                      + ", ".join(at))  # fmt: skip
    return 0


def add_parsers(sub) -> None:
    """Add ``observable``, ``evaluate``, ``validity`` and ``baselines`` to a sub-parser set."""
    o = sub.add_parser("observable", help="observable surface of the simulated scene (cached)")
    e = sub.add_parser("evaluate", help="one round against the simulator's truth")
    v = sub.add_parser("validity", help="heuristic score vs ULR render quality (simulator)")
    f = sub.add_parser("reference", help="evaluate.reference_cameras as capture-log records")
    for sp in (o, e, v, f):
        sp.add_argument("--config", default="config.yaml", help="campaign config (YAML)")
        sp.add_argument("--params", help="stage parameters as JSON (used by the workflow)")
    o.add_argument("--out", required=True, help="eval/observable_surface.npz")
    o.add_argument("--png", help="its picture (default: beside it, .png)")
    o.add_argument(
        "--cache-dir",
        help="evaluate.cache_dir: the shared cache's folder ('': none; default: the setting, "
        "else $SCENEBOT_CACHE, else $XDG_CACHE_HOME/scenebot)",
    )
    o.set_defaults(func=cmd_observable)
    e.add_argument("--scene-dir", required=True, help="results/<scene>")
    e.add_argument("--round", type=int, required=True)
    e.add_argument("--dense", help="fused cloud (PLY, robot frame) to evaluate")
    e.add_argument("--observable", help="observable-surface cache (default: <scene>/eval/...)")
    e.add_argument("--out", help="evaluation.json (default: <scene>/round_XXX/evaluation.json)")
    e.add_argument(
        "--reference", help="robot: photos: the reference cameras as log records (rule reference)"
    )
    e.set_defaults(func=cmd_evaluate)
    f.add_argument("--out", required=True, help="eval/reference_cameras.jsonl")
    f.set_defaults(func=cmd_reference)
    v.add_argument("--scene-dir", required=True, help="results/<scene>")
    v.add_argument("--round", type=int, help="round studied (default: evaluate.validity_round)")
    v.add_argument(
        "--dense",
        required=True,
        help="the campaign's proxy (final/tour/proxy.npz), or its fused cloud (PLY) to build "
        "the proxy from",
    )
    v.add_argument("--dense-round", type=int, required=True, help="round the cloud was made in")
    v.add_argument("--out", required=True, help="score_validity.json (the PNG goes beside it)")
    v.set_defaults(func=cmd_validity)
    b = sub.add_parser("baselines", help="random and frontier campaigns at the same budget")
    b.add_argument("--campaign", help="the campaign's config as JSON (used by the workflow)")
    b.add_argument("--config", default="config.yaml", help="else: campaign config (YAML)")
    b.add_argument(
        "--replot-only",
        action="store_true",
        help="run nothing: summarize the baselines already run, redraw the plot",
    )
    b.add_argument("--scene-dir", required=True, help="results/<scene> of the campaign")
    b.add_argument("--methods", default="random,frontier", help="comma-separated baselines")
    b.add_argument("--cores", type=int, default=2, help="cores of the nested runs")
    b.add_argument("--out", required=True, help="baselines.json (the PNG goes beside it)")
    b.set_defaults(func=cmd_baselines)


def main(argv: list[str] | None = None) -> int:
    from scenebot.config import ConfigError

    ap = argparse.ArgumentParser(prog="python -m scenebot.evaluate", description=__doc__)
    add_parsers(ap.add_subparsers(dest="command", required=True))
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    try:
        return args.func(args)
    except (ConfigError, ValueError, FileNotFoundError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
