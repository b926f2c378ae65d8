"""Fault soak of the NXT driver (issue 24's acceptance): round-0 captures through the brick
emulator (``robot: nxt-emulated``, the driver's exact bytes over a pseudo-terminal) with one
kind of fault per run, each beside a fault-free run with the same seed.

    TI_SKIP_VERSION_CHECK=ON .venv/bin/python benchmarks/fault_soak.py --runs 20

Kinds of fault, in turn (run ``i`` gets kind ``i mod 8`` and seed ``--seed + i``):

* ``drop 0.05`` / ``drop 0.1``: the emulator drops that fraction of all replies (any command);
* ``reboot: turn`` / ``drive`` / ``photo`` / ``sense``: the brick reboots (motors stop,
  counters reset, sensor modes lost) just before the k-th turn, drive, photo trigger or
  sensor reading (k drawn from the seed);
* ``reboot: after photo``: just after a photo's trigger, before the next turn (the issue's
  case);
* ``link loss 10 s``: the port vanishes for 10 s in the middle of the first drive;
* ``none`` (only with ``--kinds``): no fault, the two runs' natural difference.

The simulated world has noise-free sensors and slip here (the mean slip stays; see
:func:`soak_config`): the fault-free run of the same seed then takes the same decisions, and
the comparison measures what the fault did to odometry rather than sensor noise.

Every run goes through :func:`scenebot.capture.run_capture` (the capture stage itself). A run
passes when it either completed with every photo unique (by SHA-256) and decodable, and its
odometry within 2 % of the fault-free run (below), or stopped with a clear message (a
:class:`~scenebot.robot.base.RobotError` naming what to check, never a raw protocol error or
traceback); and in both cases the motors are stopped at the end (the emulator outlives the
host's robot object, so a lost link shows the tacho limit stopping the wheels: ``@limit`` in
the table, when the wheels stopped at the limit of the last motion without a stop command).

Odometry deviation: the motion between consecutive photos according to odometry (distance
driven and angle turned), compared photo by photo with the fault-free run:
``sum |d_fault - d_free| / sum |d_free|`` for distances and the same for angles; the larger of
the two, in %. Comparing motions rather than poses keeps the compass noise of the starting
heading (the odometry frame's reference) out of the figure; a fault that corrupts odometry (a
reboot's reset counters taken as motion) shows as a wrong step.

The photo budget, circle step and legs are small so a run takes seconds: the whole soak (40
captures) takes a few minutes on two cores. The emulator runs at ``--time-scale`` simulated
seconds per wall second; the driver's own settings (timeouts, retries) are the defaults.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import itertools
import logging
import math
import sys
import tempfile
import time
import traceback
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

import scenebot.robot.nxt.backend as nxt_backend
from scenebot.capture.stage import run_capture
from scenebot.capturelog import read_log
from scenebot.config import Config, validate_config
from scenebot.robot.base import RobotError

KINDS = (
    "drop 0.05",
    "drop 0.1",
    "reboot: turn",
    "reboot: drive",
    "reboot: photo",
    "reboot: after photo",
    "reboot: sense",
    "link loss 10 s",
)
MAX_DEVIATION = 0.02
MOTOR_WAIT_S = 15.0
"""After a lost link, wait this long (wall s) for the tacho limits to stop the wheels."""


@dataclass
class Outcome:
    """What one capture did."""

    completed: bool
    message: str = ""
    clear: bool = True
    photos: int = 0
    unique: int = 0
    decodable: int = 0
    steps: list[tuple[float, float]] = field(default_factory=list)  # (distance m, angle rad)
    faults: Counter = field(default_factory=Counter)
    motors_stopped: bool = True
    motors_at_limit: bool = False  # the wheels stopped at their tacho limit, not by a command
    motors_wait_s: float = 0.0
    injected: int = 0
    wall_s: float = 0.0


def soak_config(seed: int, args, faults: dict | None = None) -> Config:
    return validate_config(
        {
            "robot": "nxt-emulated",
            "seed": seed,
            # noise-free sensors and slip (the mean slip stays): a fault that adds or drops a
            # sensor read shifts the simulator's random stream, and with noise that alone can
            # turn a close call (the longest ultrasonic range) the other way; without it, the
            # two runs differ only by what the fault did. No image noise either, so a photo
            # that repeats the previous view has the same hash.
            "sim": {
                "camera": {"width": 128, "height": 96, "noise_sigma": 0.0},
                "slip": {"drive_noise": 0.0, "turn_noise": 0.0, "heading_drift_deg_per_m": 0.0},
                "sensors": {"compass_noise_deg": 0.0, "ultrasonic_noise_cm": 0.0},
            },
            "exploration": {
                "photos": args.photos,
                "circle_step_deg": 90.0,
                "drive_min_m": 0.3,
                "drive_max_m": 0.9,
            },
            "nxt_emulator": {
                "time_scale": args.time_scale,
                "faults": {"seed": seed, **(faults or {})},
            },
        }
    )


class Injector:
    """Wraps the robot and camera the capture builds, to place a fault at a kind of point."""

    def __init__(self, kind: str, rng: np.random.Generator):
        self.kind, self.rng = kind, rng
        self.calls: Counter = Counter()
        self.at = int(rng.integers(1, 4))  # the k-th call of its kind (1-based)
        self.robot = None
        self.emulator = None
        self.injected = 0

    def _next_command(self, what: str) -> None:
        faults = self.emulator.cfg.faults
        if what == "reboot":
            faults.reboot_at.append(self.emulator.command_count)
        else:  # mid-drive: after the start and a few status polls
            faults.vanish_at.append(self.emulator.command_count + 12)
        self.injected += 1

    def _wrap(self, obj, name: str, point: str, after: bool = False) -> None:
        inner = getattr(obj, name)

        def wrapped(*a, **k):
            self.calls[point] += 1
            hit = self.calls[point] == self.at and not self.injected
            if hit and not after:
                self._next_command("link" if self.kind.startswith("link") else "reboot")
            out = inner(*a, **k)
            if hit and after:
                self._next_command("reboot")
            return out

        setattr(obj, name, wrapped)

    def make_nxt_robot(self, *a, **k):
        robot, camera = _make_nxt_robot(*a, **k)
        self.robot, self.emulator = robot, robot.emulator
        robot.owned.remove(robot.emulator)  # outlive the robot: check the motors afterwards
        if self.kind == "reboot: turn":
            self._wrap(robot, "turn", "turn")
        elif self.kind == "reboot: drive":
            self.at = 1  # a short capture drives one leg
            self._wrap(robot, "drive", "drive")
        elif self.kind == "reboot: photo":
            self._wrap(camera, "capture", "photo")
        elif self.kind == "reboot: after photo":
            self._wrap(camera, "trigger", "photo", after=True)
        elif self.kind == "reboot: sense":
            self._wrap(robot, "sense", "sense")
        elif self.kind.startswith("link"):
            self.at = 1
            self._wrap(robot, "drive", "drive")
        return robot, camera


_make_nxt_robot = nxt_backend.make_nxt_robot


def run_one(seed: int, kind: str | None, args, work: Path) -> Outcome:
    """One round-0 capture with ``kind`` of fault (None: fault-free)."""
    faults: dict = {}
    if kind and kind.startswith("drop"):
        faults["drop_reply_prob"] = float(kind.split()[1])
    if kind and kind.startswith("link"):
        faults["vanish_for_s"] = 10.0
    cfg = soak_config(seed, args, faults)
    injector = Injector(kind or "", np.random.default_rng([seed, 24]))
    out_dir = work / f"seed{seed}-{(kind or 'free').replace(' ', '_').replace(':', '')}"
    capture_dir = out_dir / "round_000" / "capture"
    capture_dir.mkdir(parents=True)
    t0 = time.monotonic()
    outcome = Outcome(completed=False)
    nxt_backend.make_nxt_robot = injector.make_nxt_robot
    try:
        run_capture(cfg, capture_dir, 0, progress=False)
        outcome.completed = True
    except RobotError as exc:
        outcome.message = f"{type(exc).__name__}: {exc}"
    except Exception as exc:  # anything else is not a clear message
        outcome.message = f"{type(exc).__name__}: {exc}"
        outcome.clear = False
        if args.verbose:
            traceback.print_exc()
    finally:
        nxt_backend.make_nxt_robot = _make_nxt_robot
        emu = injector.emulator
        if emu is not None:
            t_wait = time.monotonic()
            while emu.motors_running() and time.monotonic() - t_wait < MOTOR_WAIT_S:
                time.sleep(0.05)
            outcome.motors_wait_s = time.monotonic() - t_wait
            outcome.motors_stopped = not emu.motors_running()
            wheels = [emu.motors[emu.left_port], emu.motors[emu.right_port]]
            outcome.motors_at_limit = all(
                m.tacho_limit > 0 and abs(m.tacho_count) >= m.tacho_limit - 1e-3 for m in wheels
            )
            emu.close()
    outcome.wall_s = time.monotonic() - t0
    outcome.injected = injector.injected
    log_path = capture_dir / "session.jsonl"
    if not log_path.exists():
        log_path = capture_dir / "log.jsonl"
    records = list(read_log(log_path)) if log_path.exists() else []
    photos = [r for r in records if r.get("type") == "photo"]
    outcome.faults = Counter(r["fault"] for r in records if r.get("type") == "fault")
    outcome.photos = len(photos)
    hashes, decodable = set(), 0
    for r in photos:
        data = (capture_dir / r["image"]).read_bytes()
        hashes.add(hashlib.sha256(data).hexdigest())
        img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
        decodable += img is not None and img.size > 0
    outcome.unique, outcome.decodable = len(hashes), decodable
    for a, b in itertools.pairwise(photos):
        oa, ob = a["odometry"], b["odometry"]
        dth = math.atan2(math.sin(ob["theta"] - oa["theta"]), math.cos(ob["theta"] - oa["theta"]))
        outcome.steps.append((math.hypot(ob["x"] - oa["x"], ob["y"] - oa["y"]), dth))
    return outcome


def deviation(run: Outcome, free: Outcome) -> float | None:
    """Odometry deviation of ``run`` from the fault-free run (fraction; see the module doc)."""
    if not run.completed or not free.completed or len(run.steps) != len(free.steps):
        return None
    d = np.array(run.steps) - np.array(free.steps)
    ref = np.abs(np.array(free.steps)).sum(axis=0)
    ref = np.maximum(ref, [0.1, math.radians(10.0)])  # a capture without drives or turns
    return float(np.max(np.abs(d).sum(axis=0) / ref))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--seed", type=int, default=1, help="seed of the first run")
    ap.add_argument("--photos", type=int, default=6, help="photos per capture")
    ap.add_argument("--time-scale", type=float, default=4.0, help="emulator speed-up")
    ap.add_argument("--kinds", default=None, help="comma-separated subset of the kinds")
    ap.add_argument("--keep", type=Path, default=None, help="keep the captures in this folder")
    ap.add_argument("--verbose", action="store_true", help="tracebacks of unclear stops")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    kinds = KINDS if args.kinds is None else tuple(k.strip() for k in args.kinds.split(","))
    work_ctx = (
        contextlib.nullcontext(args.keep)
        if args.keep
        else tempfile.TemporaryDirectory(prefix="fault-soak-")
    )
    header = (
        f"{'run':>3} {'seed':>4}  {'fault':<19} {'result':<9} {'photos':>6} {'uniq':>4} "
        f"{'dec':>3} {'odo dev':>7}  {'motors':<14} {'faults logged':<34} {'s':>5}  verdict"
    )
    print(header)
    print("-" * len(header))
    failures = 0
    t_all = time.monotonic()
    with work_ctx as work:
        work = Path(work)
        work.mkdir(parents=True, exist_ok=True)
        stops = []
        for i in range(args.runs):
            seed, kind = args.seed + i, kinds[i % len(kinds)]
            free = run_one(seed, None, args, work)
            run = run_one(seed, kind, args, work)
            dev = deviation(run, free)
            ok = run.motors_stopped and run.injected + (kind == "none" or kind.startswith("drop"))
            if run.completed:
                ok &= run.photos == args.photos == run.unique == run.decodable
                ok &= dev is not None and dev <= MAX_DEVIATION
            else:
                ok &= run.clear and run.unique == run.photos == run.decodable
                stops.append((i, run.message))
            ok &= free.completed and free.motors_stopped
            failures += not ok
            motors = "stopped" if run.motors_stopped else "RUNNING"
            if run.motors_stopped and run.motors_at_limit:
                motors += " @limit"
            if run.motors_wait_s > 0.2:
                motors += f" {run.motors_wait_s:.1f}s"
            logged = " ".join(f"{k}:{v}" for k, v in sorted(run.faults.items())) or "-"
            print(
                f"{i:>3} {seed:>4}  {kind:<19} {'completed' if run.completed else 'stopped':<9} "
                f"{run.photos:>6} {run.unique:>4} {run.decodable:>3} "
                f"{'-' if dev is None else f'{100 * dev:.2f}%':>7}  {motors:<14} "
                f"{logged[:34]:<34} {run.wall_s:>5.1f}  {'ok' if ok else 'FAIL'}",
                flush=True,
            )
    print("-" * len(header))
    for i, message in stops:
        print(f"run {i} stopped: {message}")
    print(
        f"{args.runs - failures} of {args.runs} runs passed ({time.monotonic() - t_all:.0f} s); "
        f"odometry deviation limit {100 * MAX_DEVIATION:.0f}%"
    )
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
