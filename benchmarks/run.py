"""Every speed figure of the project in one command, each beside a same-run reference.

    TI_SKIP_VERSION_CHECK=ON nice -n 10 .venv/bin/python benchmarks/run.py [--quick]
        [--only score,plan,...] [--sfm-full] [--arch auto|cpu] [--out benchmarks/results.md]
        [--score-baseline REV]

Prints a markdown table and writes it to ``benchmarks/results.md`` (and ``results.json``):
one row per figure with the median of repeated runs, the reference measured in the same run
(the numpy scorer, brute-force matching, scipy's Dijkstra, a plane sweep, a bare ray cast, a
from-scratch SfM run, ...), their ratio (``x faster`` = reference time / this time: above 1
the figure is faster than its reference), the machine's state beside every figure and
reference (1-minute load average, process CPU time / wall time), and the machine (CPU model,
cores, memory, GPU, library versions, load average before and after). ``--score-baseline
REV`` also times the score kernel of a git revision in the same run, interleaved with the
current one.

Groups (``--only``): ``machine`` (a numpy matrix product: a yardstick to compare machines),
``score``, ``localize``, ``plan``, ``sfm``, ``dense``, ``render`` (the simulator's photo),
``campaign`` (the stage times snakemake recorded in ``results/*/benchmarks/**/*.tsv``, not
re-measured), plus every ``benchmarks/bench_*.py`` module that defines the protocol
function below (its file stem without ``bench_`` is its group name).

Protocol for a benchmark module (e.g. ``benchmarks/bench_tour.py``)::

    def bench(quick: bool) -> list[dict]:
        # one dict per figure; times in "ms" or "s", medians of repeats
        return [{"group": "tour", "name": "ULR render 640x480 (taichi)", "median": 41.0,
                 "unit": "ms", "repeats": 5, "reference": "numpy ULR render",
                 "reference_median": 950.0, "note": "per frame"}]

``reference`` and ``reference_median`` may be None (no same-run reference). ``quick`` asks for
the smallest sizes that still measure the figure (CI, tests). A module's ``bench`` takes
precedence over the adapter of the same name below; the adapters reuse the standalone
scripts' scenes and helpers (``bench_score.build_scene``, ``bench_plan.office_points``, ...),
so the table and the scripts measure the same things.

Default sizes finish in about 15 minutes on 2 busy cores; ``--quick`` in about 5. The 260-photo
SfM acceptance run (about 8 minutes more) runs with ``--sfm-full``.
"""

from __future__ import annotations

import argparse
import datetime as dt
import importlib.util
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import time
import traceback
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
for p in (str(ROOT), str(HERE)):
    if p not in sys.path:
        sys.path.insert(0, p)

GROUP_ORDER = ["machine", "score", "localize", "plan", "sfm", "dense", "render", "campaign"]


@dataclass
class Row:
    """One figure of the table.

    Attributes:
        group: benchmark group (``score``, ``plan``, ...).
        name: what is measured, with its size.
        median: median over ``repeats`` runs, in ``unit``.
        unit: ``ms`` or ``s``.
        repeats: how many timed runs the median is over.
        reference: the same-run reference, or None.
        reference_median: its median, same unit, or None.
        note: anything that qualifies the figure (quality, rates, sizes).
        load: 1-minute load average of the machine when the figure's timed runs started.
        cpu_wall: process CPU time / wall time over the figure's timed runs (median): about
            the number of busy cores (2 for a kernel that keeps both cores of the reference
            machine busy; less when other work takes them).
        reference_load, reference_cpu_wall: the same for the reference.
        scope: ``"figure"`` when load and CPU/wall were taken around the figure's own timed
            runs, ``"group"`` when :func:`main` filled them in for the whole group (setup
            included).
    """

    group: str
    name: str
    median: float
    unit: str
    repeats: int
    reference: str | None = None
    reference_median: float | None = None
    note: str = ""
    load: float | None = None
    cpu_wall: float | None = None
    reference_load: float | None = None
    reference_cpu_wall: float | None = None
    scope: str = "figure"

    @property
    def ratio(self) -> float | None:
        """Reference time / this time (x faster than the reference), or None."""
        if self.reference_median is None or not self.median or self.median <= 0:
            return None
        return self.reference_median / self.median


def _row(d: dict | Row, group: str) -> Row:
    if isinstance(d, Row):
        return d
    known = {k: d[k] for k in Row.__dataclass_fields__ if k in d}
    known.setdefault("group", group)
    return Row(**known)


def timed(fn: Callable[[], object], repeats: int, warmup: int = 0) -> tuple[float, object]:
    """(median wall seconds over ``repeats`` calls, the last result), after ``warmup`` calls."""
    out = None
    for _ in range(warmup):
        out = fn()
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts), out


@dataclass
class Timing:
    """Medians of repeated timed calls and the machine's state while they ran.

    Attributes:
        median: median wall time of a call (s).
        cpu_wall: median of process CPU time / wall time per call.
        load: 1-minute load average before the first timed call.
        repeats: timed calls.
    """

    median: float
    cpu_wall: float
    load: float
    repeats: int


def timed_cpu(
    fns: dict[str, Callable[[], object]], repeats: int, warmup: int = 0
) -> dict[str, Timing]:
    """Time several functions in the same run, interleaved (call 1 of each, call 2 of each,
    ...) so that other work on the machine weighs on all of them alike."""
    for fn in fns.values():
        for _ in range(warmup):
            fn()
    walls: dict[str, list[float]] = {k: [] for k in fns}
    ratios: dict[str, list[float]] = {k: [] for k in fns}
    loads: dict[str, float] = {}
    for _ in range(repeats):
        for k, fn in fns.items():
            loads.setdefault(k, os.getloadavg()[0])
            t0, c0 = time.perf_counter(), time.process_time()
            fn()
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            walls[k].append(wall)
            ratios[k].append(cpu / max(wall, 1e-12))
    return {
        k: Timing(statistics.median(walls[k]), statistics.median(ratios[k]), loads[k], repeats)
        for k in fns
    }


def load_module(name: str, folder: Path = HERE):
    """Import ``<folder>/<name>.py`` (default ``benchmarks/``, not a package) as a module."""
    path = Path(folder) / f"{name}.py"
    spec = importlib.util.spec_from_file_location(f"scenebot_bench_{name}", path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # dataclasses in the module look themselves up there
    spec.loader.exec_module(mod)
    return mod


# ------------------------------------------------------------------------------- machine
def _cmd(args: list[str]) -> str | None:
    try:
        return subprocess.run(args, capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None


def describe_machine() -> dict:
    """CPU model, cores, memory, GPU, library versions, load, commit."""
    info: dict = {"date_utc": dt.datetime.now(dt.UTC).isoformat(timespec="seconds")}
    cpu = None
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    info["cpu"] = cpu or platform.processor() or platform.machine()
    info["cores"] = os.cpu_count()
    try:
        info["cores_usable"] = len(os.sched_getaffinity(0))
    except AttributeError:
        info["cores_usable"] = os.cpu_count()
    try:
        mem = Path("/proc/meminfo").read_text().split("\n")[0].split()[1]
        info["memory_gib"] = round(int(mem) / 2**20, 1)
    except (OSError, IndexError, ValueError):
        info["memory_gib"] = None
    gpu = _cmd(["nvidia-smi", "--query-gpu=name,memory.total", "--format=csv,noheader"])
    info["gpu"] = gpu or "none"
    info["os"] = platform.platform()
    info["python"] = platform.python_version()
    versions = {}
    for mod in ("numpy", "scipy", "pycolmap", "open3d", "taichi", "cv2", "snakemake"):
        try:
            m = __import__(mod)
            v = getattr(m, "__version__", None)
            if mod == "taichi" and v is None:
                v = ".".join(str(x) for x in m.__version__)
            versions[mod] = str(v)
        except Exception as exc:
            versions[mod] = f"unavailable ({type(exc).__name__})"
    try:
        import pycolmap

        versions["pycolmap_cuda"] = str(bool(pycolmap.has_cuda))
    except Exception:
        pass
    info["versions"] = versions
    info["commit"] = _cmd(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"])
    info["load_avg_start"] = [round(x, 2) for x in os.getloadavg()]
    return info


def bench_machine(quick: bool) -> list[Row]:
    """A yardstick: numpy float64 matrix product and a pure-Python loop."""
    import numpy as np

    a = np.random.default_rng(0).random((1024, 1024))
    reps = 3 if quick else 7
    t_mm, _ = timed(lambda: a @ a, reps, warmup=1)

    def loop():
        s = 0
        for i in range(1_000_000):
            s += i * i
        return s

    t_py, _ = timed(loop, reps)
    gflops = 2 * 1024**3 / t_mm / 1e9
    return [
        Row("machine", "numpy 1024x1024 float64 matmul", t_mm * 1e3, "ms", reps,
            note=f"{gflops:.1f} GFLOP/s"),
        Row("machine", "pure-Python loop, 1e6 iterations", t_py * 1e3, "ms", reps),
    ]  # fmt: skip


# --------------------------------------------------------------------------------- score
def bench_score(quick: bool, arch: str = "cpu", baseline: str | None = None) -> list[Row]:
    """Scoring speed at the acceptance point (80x60, 100 sources): taichi vs numpy.

    ``baseline``: a git revision whose score kernel (``kernel.py``, ``_tikernels.py``) is
    timed in the same run, interleaved with the current one, on the same candidates.
    """
    import numpy as np

    bs = load_module("bench_score")
    from scenebot.artifacts.mesh import decimate
    from scenebot.score.candidates import sample_candidates
    from scenebot.score.config import ScoreConfig
    from scenebot.score.kernel import init_taichi

    got = init_taichi("cpu" if arch == "cpu" else "auto")
    rng = np.random.default_rng(0)
    V0, F0, R, t, K, fs = bs.build_scene(rng)
    cfg = ScoreConfig()
    V, F = decimate(V0, F0, cfg.max_triangles)
    n = 400 if quick else 2000
    cands = sample_candidates(fs, n, rng, "bench")
    w, h, S = 80, 60, 100
    backend = "cpu" if got not in ("cuda", "vulkan") else "auto"
    tk, ref = bs.scorers(V, F, R, t, K, w, h, S, cfg.batch_size, backend)
    fns = {"taichi": lambda: tk.score(cands[:n])}
    if baseline:
        old, _ = bs.scorers(V, F, R, t, K, w, h, S, cfg.batch_size, backend, reference=False,
                            kernel=bs.kernel_at(baseline))  # fmt: skip
        fns["baseline"] = lambda: old.score(cands[:n])
    reps = 3 if quick else 5
    tim = timed_cpu(fns, reps, warmup=1)
    m = 12 if quick else 40
    t_np = timed_cpu({"numpy": lambda: ref.score(cands[:m])}, 3)["numpy"]
    b = ref.score(cands[:m]).score_deg
    label = (f"score one candidate, {w}x{h} px, {S} sources, {len(F)} triangles "
             f"(taichi {got}, {n} candidates in batches of {cfg.batch_size})")  # fmt: skip
    rows = []
    for k, scorer in (("taichi", tk), ("baseline", old if baseline else None)):
        if k not in tim:
            continue
        a = scorer.score(cands[:m]).score_deg
        diff = float(np.nanmean(np.abs(a - b)))
        per = tim[k].median / n * 1e3
        note = (f"{1e3 / per:.0f} vs {m / t_np.median:.1f} evals/s; mean |score diff| "
                f"{diff:.4f} deg")  # fmt: skip
        if k == "taichi" and baseline:
            note += (f"; {tim['baseline'].median / tim['taichi'].median:.2f} x the kernel at "
                     f"{baseline} (same run, interleaved)")  # fmt: skip
        rows.append(Row(
            "score", label if k == "taichi" else f"{label}, kernel at {baseline}", per, "ms",
            reps, "numpy reference scorer", t_np.median / m * 1e3, note,
            load=tim[k].load, cpu_wall=tim[k].cpu_wall, reference_load=t_np.load,
            reference_cpu_wall=t_np.cpu_wall,
        ))  # fmt: skip
    return rows


# ------------------------------------------------------------------------------ localize
def bench_localize(quick: bool) -> list[Row]:
    """FLANN vs brute-force matching, whole localization, DLT vs pycolmap pose estimation."""
    import cv2
    import numpy as np
    import pycolmap

    bl = load_module("bench_localize")
    from scenebot.config import SimConfig
    from scenebot.localize import LocalizationMap, LocalizeConfig, localize
    from scenebot.localize.index import DescriptorIndex, MapDescriptors
    from scenebot.localize.match import match_to_map
    from scenebot.scene.office import office
    from scenebot.sim.world import SimWorld

    rows: list[Row] = []
    scene = office(7)
    world = SimWorld(scene, SimConfig(), scene.start, seed=0)
    md = bl.build_office_map(world, 4, 12)  # cached in benchmarks/out/
    intr = world.intrinsics
    cam = pycolmap.Camera(model="PINHOLE", width=intr.width, height=intr.height,
                          params=[intr.fx, intr.fy, intr.cx, intr.cy])  # fmt: skip
    reps = 3 if quick else 5
    # --- matching: 1,000 query descriptors against a 160,000-row map (bench_localize's data)
    n_map, n_q = (40_000, 500) if quick else (160_000, 1000)
    rng = np.random.default_rng(7)
    base = md.descriptors
    rows_i = np.tile(np.arange(len(base)), math.ceil(n_map / len(base)))[:n_map]
    noise = rng.normal(0, 4.0, (n_map, 128)) * (np.arange(n_map) >= len(base))[:, None]
    big = np.clip(base[rows_i] + noise, 0, 255).astype(np.uint8)
    bigmap = MapDescriptors(md.point_ids[rows_i], md.xyz[rows_i], big)
    q_rows = rng.choice(len(base), n_q, replace=False)
    q = np.clip(base[q_rows] + rng.normal(0, 6.0, (n_q, 128)), 0, 255).astype(np.uint8)
    checks = LocalizeConfig().flann_checks
    t0 = time.perf_counter()
    index = DescriptorIndex(bigmap.descriptors, trees=4, checks=checks)
    build_s = time.perf_counter() - t0
    loc = LocalizeConfig()
    t_fl, _ = timed(lambda: match_to_map(q, index, bigmap, knn=loc.knn, ratio=loc.ratio), reps)
    bf = cv2.BFMatcher(cv2.NORM_L2)
    qf, mf = q.astype(np.float32), bigmap.descriptors.astype(np.float32)
    t_bf, exact = timed(lambda: bf.knnMatch(qf, mf, k=1), 1 if quick else 3)
    idx_f, _ = index.knn(q, 1)
    exact_pid = bigmap.point_ids[[e[0].trainIdx for e in exact]]
    recall = float(np.mean(bigmap.point_ids[idx_f[:, 0]] == exact_pid))
    rows.append(Row("localize", f"match {n_q} descriptors to a {n_map // 1000}k-row map "
                    f"(FLANN, 4 trees, {checks} checks)", t_fl * 1e3, "ms", reps,
                    "brute force (OpenCV BFMatcher, exact)", t_bf * 1e3,
                    f"nearest-point recall {recall:.3f}; index build {build_s:.1f} s"))  # fmt: skip
    # --- whole localization of one photo, and its pose step: DLT (paper) vs pycolmap
    plane = {"camera_plane_z_m": scene.floor_z + world.cfg.camera.height_m}
    rng = np.random.default_rng(11)
    for _ in range(50):
        R, c = bl.camera_at(world, bl.free_spot(world, rng, 0.5), rng.uniform(0, 2 * math.pi))
        img = world.renderer.render(intr, R, c, rng)
        if localize(img, LocalizationMap(md, cam), LocalizeConfig(**plane)).ok:
            break
    res = {}
    for method in ("dlt", "pycolmap"):
        cfg = LocalizeConfig(method=method, **plane)
        lmap = LocalizationMap(md, cam, cfg=cfg)
        tim = []
        for _ in range(reps):
            est = localize(img, lmap, cfg)
            tim.append([est.timings_s[k] * 1e3 for k in ("extract", "match", "pose", "total")])
        res[method] = np.median(np.array(tim), axis=0)
    d, p = res["dlt"], res["pycolmap"]
    rows.append(Row("localize", f"whole localization of a 640x480 photo (DLT, first octave "
                    f"{LocalizeConfig().sift_first_octave})", d[3], "ms", reps,
                    "same with the pycolmap estimator", p[3],
                    f"extract {d[0]:.0f} ms, match {d[1]:.0f} ms, pose {d[2]:.0f} ms; map "
                    f"{len(md.point_ids)} descriptors"))  # fmt: skip
    rows.append(Row("localize", "pose from matches: RANSAC + DLT + refinement (paper)", d[2],
                    "ms", reps, "pycolmap P3P LO-RANSAC + refinement", p[2]))  # fmt: skip
    return rows


# ---------------------------------------------------------------------------------- plan
def bench_plan(quick: bool) -> list[Row]:
    """KDE grid + A* + simplification on 100x100 and 1000x1000 grids vs scipy Dijkstra."""
    import numpy as np

    bp = load_module("bench_plan")
    from scenebot.plan import PlanConfig, build_navgrid
    from scenebot.plan.astar import astar, effective_cost
    from scenebot.plan.simplify import simplify_path

    rng = np.random.default_rng(0)
    pts = bp.office_points(rng)
    cams = np.array([[0.4, 0.4], [5.6, 4.6]])
    start, goal = np.array([0.5, 1.5]), np.array([4.8, 0.5])
    rows = []
    for n in (100, 1000):
        cfg = PlanConfig(n_cells=n, margin_m=0.4)
        reps = (5 if n == 100 else 3) if quick else (7 if n == 100 else 3)
        tot, parts = [], []
        for _ in range(reps):
            t0 = time.perf_counter()
            grid = build_navgrid(pts, cams, cfg)
            t1 = time.perf_counter()
            g = grid.geometry
            s, t = tuple(g.cell_of(start)), tuple(g.cell_of(goal))
            res = astar(grid.cost_per_m, grid.lethal, s, t, g.cell_m)
            t2 = time.perf_counter()
            simplify_path(res.cells, effective_cost(grid.cost_per_m, grid.lethal), g.cell_m)
            t3 = time.perf_counter()
            tot.append(t3 - t0)
            parts.append((t1 - t0, t2 - t1, t3 - t2))
        med = np.median(np.array(parts), axis=0) * 1e3
        ref = statistics.median(
            bp.reference_dijkstra_s(effective_cost(grid.cost_per_m, grid.lethal), s, g.cell_m)
            for _ in range(3)
        )
        rows.append(Row("plan", f"KDE + A* + simplify, {g.shape[1]}x{g.shape[0]} grid",
                        statistics.median(tot) * 1e3, "ms", reps,
                        "scipy Dijkstra from the start cell (search only)", ref * 1e3,
                        f"kde {med[0]:.1f} / A* {med[1]:.1f} / simplify {med[2]:.1f} ms; "
                        f"budget {bp.BUDGET_S[n] * 1e3:g} ms; A* alone {med[1] / (ref * 1e3):.2f}"
                        " x Dijkstra time"))  # fmt: skip
    return rows


# ----------------------------------------------------------------------------------- sfm
def bench_sfm(quick: bool, full: bool = False, work: Path | None = None) -> list[Row]:
    """SfM stage on a small fixed capture set: round update vs from scratch (the reference).

    The small set is the ray-cast synthetic room of ``bench_sfm`` (two rounds); ``full``
    also runs the issue's acceptance case (200 + 60 simulator photos at 640x480).
    """
    import logging
    import shutil

    logging.getLogger("scenebot").setLevel(logging.WARNING)
    bsf = load_module("bench_sfm")
    from scenebot.sfm.config import SfmConfig
    from scenebot.sfm.stage import SfmInputs, SfmOutputs

    work = Path(work or "/tmp/scenebot_bench/sfm")
    rows = []
    cases = [("synthetic room", work / "synthetic", None)]
    if full:
        cases.append(("simulated office 200 + 60 photos", work / "sim", (200, 60)))
    for label, scene, sim in cases:
        if sim is None:
            bsf.make_synthetic_rounds(scene)
        else:
            bsf.make_sim_rounds(scene, ROOT / "config.yaml", *sim)
        caps = [scene / "round_000/capture", scene / "round_001/capture"]
        offset_of = getattr(bsf, "camera_offset_from_log", None)  # the camera mount, if known
        cfg = SfmConfig(plots=False)
        if offset_of is not None and "camera_offset_m" in SfmConfig.model_fields:
            cfg = SfmConfig(plots=False, camera_offset_m=offset_of(caps[0] / "log.jsonl"))
        reps = 1 if (quick or sim) else 2
        scratch, update, reps_done = [], [], 0
        for _ in range(reps):
            runs = work / f"runs_{scene.name}"
            shutil.rmtree(runs, ignore_errors=True)
            s, rep_s = bsf.timed_run(cfg, SfmInputs(runs / "a/database.db", caps),
                                     SfmOutputs(runs / "a/round_001/sfm"))  # fmt: skip
            bsf.timed_run(cfg, SfmInputs(runs / "b/database.db", caps[:1]),
                          SfmOutputs(runs / "b/round_000/sfm"))  # fmt: skip
            u, rep_u = bsf.timed_run(
                cfg,
                SfmInputs(runs / "b/database.db", caps, previous_model=runs / "b/round_000/sfm"),
                SfmOutputs(runs / "b/round_001/sfm"),
            )
            scratch.append(s)
            update.append(u)
            reps_done += 1
        acc = rep_s.get("accuracy", {})
        pos = acc.get("position_error_m", {}).get("median", float("nan")) * 100
        n0 = sum(1 for _ in (caps[0] / "images").glob("*.jpg"))
        rows.append(Row("sfm", f"sfm stage from scratch, {label} ({rep_s['photos']} photos)",
                        statistics.median(scratch), "s", reps_done, None, None,
                        f"registered {rep_s['registered']}/{rep_s['photos']}, median position "
                        f"error {pos:.2f} cm"))  # fmt: skip
        rows.append(Row("sfm", f"sfm round update, {label} (+{rep_u['photos'] - n0} photos to "
                        f"{n0})", statistics.median(update), "s", reps_done,
                        "the same from scratch", statistics.median(scratch),
                        f"mode {rep_u.get('mapping_mode')}; registered "
                        f"{rep_u['registered']}"))  # fmt: skip
    return rows


# --------------------------------------------------------------------------------- dense
def bench_dense(quick: bool, arch: str = "cpu") -> list[Row]:
    """One depth map (photometric + geometric + filter) vs a numpy/OpenCV plane sweep."""
    bd = load_module("bench_dense")
    from scenebot.dense.config import PatchMatchConfig
    from scenebot.dense.evaluate import depth_map_metrics
    from scenebot.dense.patchmatch import PatchMatchSolver
    from scenebot.taichi_setup import init_taichi

    got = init_taichi(arch, 2 if arch == "cpu" else -1)
    w, h = (320, 240) if quick else (640, 480)
    n_src = 4
    views, truth = bd.make_views(w, h, n_src + 1)
    mid = n_src // 2
    ref, gt = views[mid], truth[mid]
    srcs = [v for i, v in enumerate(views) if i != mid]
    solver = PatchMatchSolver(PatchMatchConfig())
    rng = (0.5, 4.5)
    src_photo = [solver.estimate(v, [x for x in views if x is not v], rng).depth for v in srcs]

    def full():
        p = solver.estimate(ref, srcs, rng)
        g = solver.estimate(ref, srcs, rng, src_depths=src_photo, init=(p.depth, p.normal))
        return solver.filter(ref, srcs, g, src_photo)

    reps = 2 if quick else 3
    t_pm, r = timed(full, reps, warmup=1)
    t_ps, d = timed(lambda: bd.plane_sweep(ref, srcs, rng), 1 if quick else 2)
    m_pm, m_ps = depth_map_metrics(r.depth, gt), depth_map_metrics(d, gt)
    return [
        Row("dense", f"depth map {w}x{h}, {n_src} sources: PatchMatch photometric + geometric "
            f"+ filter (taichi {got})", t_pm, "s", reps, "plane sweep, 96 planes (numpy/OpenCV)",
            t_ps, f"within 2%: {m_pm['accuracy']:.3f} of {m_pm['coverage']:.3f} covered vs "
            f"{m_ps['accuracy']:.3f} of {m_ps['coverage']:.3f}"),
        bench_dense_processes(bd, quick),
    ]  # fmt: skip


def bench_dense_processes(bd, quick: bool) -> Row:
    """The whole dense stage on the CPU, per view: its views in 2 worker processes vs all in
    one process (``dense.num_threads`` 2 vs 1), interleaved, each in a fresh process."""
    import numpy as np

    w, h, per_row = (320, 240, 4) if quick else (640, 480, 6)
    n, reps = 2 * per_row, 1 if quick else 2
    res = bd.stage_processes(HERE / "out" / "dense_processes", w, h, per_row, (1, 2), reps)
    one, two = res[1], res[2]
    same = all(np.array_equal(a, b) for a, b in zip(one["maps"], two["maps"], strict=True))
    return Row("dense", f"dense stage, {n} synthetic views {w}x{h}, taichi on the CPU: views "
               "in 2 worker processes (num_threads 2), s per view", two["wall_s"] / n, "s", reps,
               "the same in one process (num_threads 1)", one["wall_s"] / n,
               f"same depth maps: {same}; within 2%: {two['metrics']['accuracy']:.3f} of "
               f"{two['metrics']['coverage']:.3f} covered; includes the workers' start",
               load=two["load"], cpu_wall=two["cpu_wall"], reference_load=one["load"],
               reference_cpu_wall=one["cpu_wall"])  # fmt: skip


# -------------------------------------------------------------------------------- render
def bench_render(quick: bool) -> list[Row]:
    """The simulator's photo (640x480, office): full render vs a bare ray cast of its pixels."""
    import numpy as np

    from scenebot.config import SimConfig
    from scenebot.scene.office import office
    from scenebot.sim.renderer import Renderer, look_rotation
    from scenebot.sim.world import SimWorld

    scene = office(7)
    cfg = SimConfig()
    world = SimWorld(scene, cfg, scene.start, seed=0)
    intr = world.intrinsics
    rng = np.random.default_rng(3)
    poses = []
    lo, hi = scene.bounds
    while len(poses) < (3 if quick else 6):
        xy = rng.uniform(lo[:2] + 0.3, hi[:2] - 0.3)
        if world.collision_map.clearance_at(xy) > 0.3:
            th = rng.uniform(0, 2 * math.pi)
            poses.append((look_rotation(th), np.array([*xy, cfg.camera.height_m])))
    plain = Renderer(scene, noise_sigma=cfg.camera.noise_sigma, antialias=False)
    aa = world.renderer
    k = [0]

    def cycle(fn):
        def f():
            R, c = poses[k[0] % len(poses)]
            k[0] += 1
            return fn(R, c)

        return f

    def bare(R, c):
        d = plain._pixel_rays(intr, R)
        return plain.cast(np.broadcast_to(c, d.shape), d)

    reps = len(poses)
    t_ray, _ = timed(cycle(bare), reps, warmup=1)
    t_aa, _ = timed(cycle(lambda R, c: aa.render(intr, R, c, rng)), reps, warmup=1)
    t_pl, _ = timed(cycle(lambda R, c: plain.render(intr, R, c, rng)), reps, warmup=1)
    ref = "open3d ray cast of the same 640x480 rays (geometry only)"
    return [
        Row("render", f"simulator photo {intr.width}x{intr.height}, office, antialiased "
            "(the default)", t_aa * 1e3, "ms", reps, ref, t_ray * 1e3,
            f"{len(scene.triangles)} triangles"),
        Row("render", f"simulator photo {intr.width}x{intr.height}, office, no antialiasing",
            t_pl * 1e3, "ms", reps, ref, t_ray * 1e3),
    ]  # fmt: skip


# ------------------------------------------------------------------------------ campaign
def bench_campaign(quick: bool, results: Path = ROOT / "results") -> list[Row]:
    """Whole campaigns: wall and CPU time per stage, summed over its jobs, as Snakemake
    recorded them (``results/*/benchmarks/``, read by :mod:`scenebot.timing`; not re-measured).
    """
    from scenebot.timing import by_stage, read_benchmarks

    rows = []
    for bench in sorted(Path(results).glob("*/benchmarks")):
        jobs = read_benchmarks(bench)
        if not jobs:
            continue
        scene = bench.parent.name
        newest = max(p.stat().st_mtime for p in bench.glob("**/*.tsv"))
        when = dt.datetime.fromtimestamp(newest, dt.UTC).strftime("%Y-%m-%d %H:%M")
        stages = by_stage(jobs)
        for name, st in stages.items():
            rows.append(Row(
                "campaign", f"{scene}: {name} ({st['jobs']} jobs)", st["seconds"], "s", 1,
                note=f"CPU {st['cpu_seconds']:.0f} s, CPU/wall {st['cpu_per_wall']}, max RSS "
                f"{st['max_rss_mb']:.0f} MB; recorded by snakemake, last job {when} UTC",
                cpu_wall=st["cpu_per_wall"],
            ))  # fmt: skip
        wall = sum(st["seconds"] for st in stages.values())
        cpu = sum(st["cpu_seconds"] for st in stages.values())
        rows.append(Row("campaign", f"{scene}: all jobs", wall, "s", 1,
                        note=f"CPU {cpu:.0f} s; sum of the jobs' wall times",
                        cpu_wall=round(cpu / wall, 2) if wall else None))  # fmt: skip
    return rows


# ---------------------------------------------------------------------------------- main
def _fmt(x: float | None) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    if x >= 100:
        return f"{x:.0f}"
    if x >= 10:
        return f"{x:.1f}"
    if x >= 0.1:
        return f"{x:.2f}"
    return f"{x:.3g}"


def markdown(rows: list[Row], machine: dict, args_line: str, seconds: float) -> str:
    """The table and the machine, as markdown."""
    v = machine["versions"]
    lines = [
        f"Measured {machine['date_utc']} by `{args_line}` in {seconds / 60:.1f} min "
        f"(commit {machine.get('commit') or '?'}).",
        "",
        f"Machine: {machine['cpu']}, {machine['cores']} cores ({machine['cores_usable']} usable), "
        f"{machine['memory_gib']} GiB RAM, GPU: {machine['gpu']}; {machine['os']}; Python "
        f"{machine['python']}, "
        + ", ".join(f"{k} {val}" for k, val in v.items())
        + f". Load average at start {machine['load_avg_start']}, at end "
        f"{machine.get('load_avg_end')} (other work on the machine slows every figure).",
        "",
        "Medians of the repeats; `x faster` = reference time / this time (above 1: faster than "
        "the reference measured in the same run). `load` = the 1-minute load average when the "
        "timed runs began and `CPU/wall` = process CPU time / wall time over them (about the "
        "cores in use), for the figure and then its reference; in italics where they were "
        "taken around the whole group (setup included) rather than the figure's own runs.",
        "",
        "| group | measurement | median | load | CPU/wall | reference (same run) "
        "| reference median | ref. load | ref. CPU/wall | x faster | repeats | note |",
        "|---|---|---:|---:|---:|---|---:|---:|---:|---:|---:|---|",
    ]

    def cell(text: str | None) -> str:
        return (text or "-").replace("|", "\\|")

    def state(x: float | None, scope: str) -> str:
        if x is None or (isinstance(x, float) and math.isnan(x)):
            return "-"
        return f"*{x:.2f}*" if scope == "group" else f"{x:.2f}"

    for r in rows:
        ratio = r.ratio
        ref_unit = " " + r.unit if r.reference_median is not None else ""
        lines.append(
            f"| {r.group} | {cell(r.name)} | {_fmt(r.median)} {r.unit} "
            f"| {state(r.load, r.scope)} | {state(r.cpu_wall, r.scope)} | {cell(r.reference)} "
            f"| {_fmt(r.reference_median)}{ref_unit} | {state(r.reference_load, r.scope)} "
            f"| {state(r.reference_cpu_wall, r.scope)} | {_fmt(ratio)} | {r.repeats} "
            f"| {cell(r.note) if r.note else ''} |"
        )
    return "\n".join(lines) + "\n"


def discover(
    quick: bool, arch: str, full_sfm: bool, only: set[str] | None, folder: Path = HERE
) -> dict:
    """Group name -> callable returning rows: built-in adapters, overridden by the modules
    ``<folder>/bench_*.py`` that define ``bench(quick)``."""
    groups: dict[str, Callable[[], list]] = {
        "machine": lambda: bench_machine(quick),
        "score": lambda: bench_score(quick, arch),
        "localize": lambda: bench_localize(quick),
        "plan": lambda: bench_plan(quick),
        "sfm": lambda: bench_sfm(quick, full_sfm),
        "dense": lambda: bench_dense(quick, arch),
        "render": lambda: bench_render(quick),
        "campaign": lambda: bench_campaign(quick),
    }
    for path in sorted(Path(folder).glob("bench_*.py")):
        name = path.stem.removeprefix("bench_")
        if only is not None and name not in only:
            continue
        try:
            text = path.read_text()
        except OSError:
            continue
        if "def bench(" not in text:
            continue  # no protocol function: its adapter above (if any) runs it

        def call(stem=path.stem):
            return load_module(stem, folder).bench(quick)

        groups[name] = call
    order = GROUP_ORDER + sorted(k for k in groups if k not in GROUP_ORDER)
    return {k: groups[k] for k in order if k in groups and (only is None or k in only)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smallest sizes (about 5 minutes)")
    ap.add_argument("--only", help="comma-separated groups (machine,score,localize,...)")
    ap.add_argument("--sfm-full", action="store_true", help="also the 260-photo SfM run")
    ap.add_argument("--arch", choices=["auto", "cpu"], default="auto",
                    help="taichi arch of score and dense (auto: the GPU when there)")  # fmt: skip
    ap.add_argument("--out", type=Path, default=HERE / "results.md",
                    help="markdown output (the JSON goes beside it)")  # fmt: skip
    ap.add_argument("--no-write", action="store_true", help="print only")
    ap.add_argument("--score-baseline", metavar="REV",
                    help="also time the score kernel of this git revision, same run")  # fmt: skip
    args = ap.parse_args(argv)
    only = set(args.only.split(",")) if args.only else None
    t_start = time.perf_counter()
    machine = describe_machine()
    rows: list[Row] = []
    failures: dict[str, str] = {}
    groups = discover(args.quick, args.arch, args.sfm_full, only)
    if args.score_baseline and "score" in groups:
        groups["score"] = lambda: bench_score(args.quick, args.arch, args.score_baseline)
    for name, fn in groups.items():
        t0 = time.perf_counter()
        c0, load0 = time.process_time(), os.getloadavg()[0]
        print(f"[{time.strftime('%H:%M:%S')}] {name} ...", file=sys.stderr, flush=True)
        try:
            got = [_row(r, name) for r in fn()]
        except Exception as exc:
            failures[name] = f"{type(exc).__name__}: {exc}"
            traceback.print_exc()
            got = [Row(name, "FAILED", float("nan"), "s", 0, note=failures[name][:200])]
        group_cpu_wall = (time.process_time() - c0) / max(time.perf_counter() - t0, 1e-9)
        for r in got:
            if r.load is None and r.cpu_wall is None:  # the group did not state its own
                r.load, r.cpu_wall, r.scope = load0, group_cpu_wall, "group"
                if r.reference_median is not None:
                    r.reference_load, r.reference_cpu_wall = load0, group_cpu_wall
        rows += got
        print(f"    {name}: {len(got)} rows in {time.perf_counter() - t0:.0f} s",
              file=sys.stderr, flush=True)  # fmt: skip
    machine["load_avg_end"] = [round(x, 2) for x in os.getloadavg()]
    seconds = time.perf_counter() - t_start
    given = argv if argv is not None else sys.argv[1:]
    line = " ".join(["python benchmarks/run.py", *given])
    md = markdown(rows, machine, line.strip(), seconds)
    print(md)
    if not args.no_write:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text("# scenebot benchmarks\n\n" + md)
        data = {
            "machine": machine,
            "seconds": seconds,
            "command": line.strip(),
            "rows": [asdict(r) | {"ratio": r.ratio} for r in rows],
            "failures": failures,
        }
        args.out.with_suffix(".json").write_text(json.dumps(data, indent=1, default=str) + "\n")
        print(f"written: {args.out} and {args.out.with_suffix('.json')}", file=sys.stderr)
    return 1 if failures else 0


if __name__ == "__main__":
    raise SystemExit(main())
