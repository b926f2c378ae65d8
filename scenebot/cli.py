"""The ``scenebot`` command line: every stage callable outside Snakemake.

Examples::

    scenebot capture --config config.yaml --out results/office/round_000/capture
    scenebot schema --write
    scenebot check-config config.yaml
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from scenebot.config import ConfigError, from_sections, load_config, validate_config


def _config(args) -> object:
    if getattr(args, "params", None):
        return from_sections(args.params)
    return load_config(args.config)


def cmd_capture(args) -> int:
    from scenebot.capture import run_capture

    cfg = _config(args)
    summary = run_capture(cfg, Path(args.out), args.round, progress=not args.no_progress)
    print(json.dumps(summary))
    return 0


def cmd_schema(args) -> int:
    from scenebot.config import json_schema, write_schema

    if args.write:
        print(write_schema())
    else:
        print(json.dumps(json_schema(), indent=2, sort_keys=True))
    return 0


def cmd_check_config(args) -> int:
    import yaml

    cfg = validate_config(yaml.safe_load(Path(args.path).read_text()), args.path)
    print(f"{args.path}: valid (scene {cfg.scene!r}, robot {cfg.robot!r})")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="scenebot", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)

    def with_config(sp):
        sp.add_argument("--config", default="config.yaml", help="campaign config (YAML)")
        sp.add_argument("--params", help="stage parameters as JSON (used by the workflow)")

    c = sub.add_parser("capture", help="round-0 capture: random exploration")
    with_config(c)
    c.add_argument("--out", required=True, help="capture folder (round_000/capture)")
    c.add_argument("--round", type=int, default=0)
    c.add_argument("--no-progress", action="store_true")
    c.set_defaults(func=cmd_capture)

    s = sub.add_parser("schema", help="print (or --write) the config JSON schema")
    s.add_argument("--write", action="store_true")
    s.set_defaults(func=cmd_schema)

    k = sub.add_parser("check-config", help="validate a config file")
    k.add_argument("path")
    k.set_defaults(func=cmd_check_config)
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
