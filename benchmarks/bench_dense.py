"""Speed and quality of the dense depth estimation on synthetic 640x480 views.

Compares, on the same reference view and sources (true cameras, known depth):

* ``plane-sweep (ref)``: a numpy/OpenCV fronto-parallel plane sweep with box-filtered NCC and
  top-k source aggregation (the kind of prototype the issue measured), the same-run reference;
* ``taichi photometric``: the PatchMatch photometric pass (coarse-to-fine);
* ``taichi full``: photometric + geometric pass + filter (what the stage runs per view);
* ``taichi all views``: the stage's three passes over every view of the set (each view with all
  the others as sources), per view;
* ``colmap cuda``: pycolmap.patch_match_stereo on the same views and sources, per view, only
  where pycolmap has CUDA (``--colmap``).

``--processes 1 2`` runs the whole stage on the CPU on a synthetic capture once per
``dense.num_threads`` (worker processes), interleaved, and prints seconds per view, CPU/wall,
the load average and whether the depth maps are the same.

``--export DIR`` writes the views as a COLMAP dense workspace (``DIR/dense``) and as
``DIR/views.npz``; ``--views DIR/views.npz`` runs the taichi rows on those views without
rendering (numpy, OpenCV, taichi and pydantic only: no open3d), and ``--colmap DIR`` runs COLMAP
on the workspace, so a GPU machine compares both on the same pixels.

Each row: median wall time over repeats (after one warm-up that compiles the kernels), median
process CPU time, the ratio to the reference, and quality: coverage (fraction of pixels with a
depth; the unfiltered passes give every pixel one) and accuracy (fraction of those within 2 % of
the true depth). Run ``python benchmarks/bench_dense.py --help``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path
from typing import TYPE_CHECKING

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")

import cv2
import numpy as np

from scenebot.dense.config import DenseConfig, PatchMatchConfig
from scenebot.dense.evaluate import depth_map_metrics

if TYPE_CHECKING:  # imported where used: --views runs without open3d and pycolmap
    from scenebot.dense.patchmatch import StereoView


def plane_sweep(
    ref: StereoView,
    srcs: list[StereoView],
    depth_range: tuple[float, float],
    num_planes: int = 96,
    radius: int = 3,
    top_k: int = 2,
    max_cost: float = 0.5,
) -> np.ndarray:
    """Fronto-parallel plane sweep (reference method).

    Returns:
        (H, W) float32 depth, 0 where the best cost exceeds ``max_cost``.
    """
    h, w = ref.gray.shape
    ksize = (2 * radius + 1, 2 * radius + 1)
    r = ref.gray.astype(np.float32)
    mr = cv2.boxFilter(r, -1, ksize)
    vr = cv2.boxFilter(r * r, -1, ksize) - mr * mr
    best = np.full((h, w), np.inf, np.float32)
    best_d = np.zeros((h, w), np.float32)
    n = np.array([0.0, 0.0, -1.0])
    inv = np.linspace(1.0 / depth_range[1], 1.0 / depth_range[0], num_planes)
    for d in 1.0 / inv:
        costs = []
        for s in srcs:
            Rr = s.R @ ref.R.T
            t = s.t - Rr @ ref.t
            # plane z = d in the reference frame: n . X = -d
            Hm = s.K @ (Rr + np.outer(t, n) / -d) @ np.linalg.inv(ref.K)
            # warp source into the reference (pixel centres at +0.5 on both sides)
            S = np.array([[1, 0, 0.5], [0, 1, 0.5], [0, 0, 1.0]])
            Hpix = np.linalg.inv(S) @ Hm @ S
            warped = cv2.warpPerspective(
                s.gray, Hpix, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                borderValue=-1.0,
            )  # fmt: skip
            valid = cv2.erode((warped >= 0).astype(np.uint8), np.ones(ksize, np.uint8)) > 0
            ms = cv2.boxFilter(warped, -1, ksize)
            vs = cv2.boxFilter(warped * warped, -1, ksize) - ms * ms
            cov = cv2.boxFilter(r * warped, -1, ksize) - mr * ms
            ncc = cov / np.sqrt(np.maximum(vr * vs, 1e-10))
            costs.append(np.where(valid, 1.0 - ncc, 2.0))
        c = np.sort(np.stack(costs), axis=0)[:top_k].mean(0)
        better = c < best
        best[better] = c[better]
        best_d[better] = d
    return np.where(best < max_cost, best_d, 0.0).astype(np.float32)


def make_views(width: int, height: int, num: int) -> tuple[list, list[np.ndarray]]:
    """``num`` views of the box room across y (true cameras), grey from a JPEG (quality 95)."""
    from scenebot.dense.patchmatch import StereoView
    from scenebot.testing.dense import box_room_scene, intrinsics, look_at_pose, render_view

    sc = box_room_scene()
    K = intrinsics(width, height)
    views, truth = [], []
    for k, y in enumerate(np.linspace(-0.3, 0.3, num)):
        R, t = look_at_pose(np.array([0.0, y, 0.0]), 0.0)
        img, depth, _ = render_view(sc, K, R, t, width, height)
        _, jpg = cv2.imencode(
            ".jpg", cv2.cvtColor(img, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 95]
        )
        gray = cv2.cvtColor(cv2.imdecode(jpg, cv2.IMREAD_COLOR), cv2.COLOR_BGR2GRAY)
        views.append(StereoView(f"v{k}", gray.astype(np.float32) / 255.0, K, R, t))
        truth.append(depth)
    return views, truth


def export_views(folder: Path, width: int, height: int, num: int) -> tuple[list, list]:
    """The :func:`make_views` cameras as a COLMAP dense workspace and an ``.npz``.

    Writes ``folder/capture`` (photos, sparse model), ``folder/dense`` (pycolmap's undistorted
    workspace, every view with all the others as sources) and ``folder/views.npz`` (the grey
    views the taichi rows read, loaded from the workspace as the stage loads them, and their
    true depth). Returns the views and true depths.
    """
    import shutil

    from scenebot.dense import workspace as ws
    from scenebot.testing.dense import box_room_scene, make_dataset

    shutil.rmtree(folder, ignore_errors=True)
    centers = np.stack([np.zeros(num), np.linspace(-0.3, 0.3, num), np.zeros(num)], axis=1)
    rec, synth = make_dataset(folder / "capture", box_room_scene(), centers, np.zeros(num),
                              width, height)  # fmt: skip
    dense = folder / "dense"
    rec = ws.undistort(folder / "capture" / "sparse", folder / "capture" / "images", dense,
                       max(width, height))  # fmt: skip
    ids = sorted(rec.images)
    names = [rec.image(i).name for i in ids]
    ws.write_configs(dense, {n: [m for m in names if m != n] for n in names})
    views = [ws.load_view(rec, i, dense) for i in ids]
    truth = [next(v.depth for v in synth if v.name == n) for n in names]
    np.savez_compressed(
        folder / "views.npz",
        names=np.array(names),
        gray=np.stack([np.round(v.gray * 255).astype(np.uint8) for v in views]),
        K=np.stack([v.K for v in views]),
        R=np.stack([v.R for v in views]),
        t=np.stack([v.t for v in views]),
        depth=np.stack(truth).astype(np.float32),
    )
    return views, truth


def load_views(path: Path) -> tuple[list, list[np.ndarray]]:
    """Views and true depths written by :func:`export_views`."""
    from scenebot.dense.patchmatch import StereoView

    z = np.load(path)
    views = [
        StereoView(str(n), g.astype(np.float32) / 255.0, K, R, t)
        for n, g, K, R, t in zip(z["names"], z["gray"], z["K"], z["R"], z["t"], strict=True)
    ]
    return views, list(z["depth"])


def print_per_view(label: str, names: list[str], metrics: list[dict]) -> None:
    """One line: each view's coverage / fraction within 2 %."""
    cells = [
        f"{n} {m['coverage']:.3f}/{m['accuracy']:.3f}" for n, m in zip(names, metrics, strict=True)
    ]
    print(f"# {label}, coverage/within 2% per view: " + ", ".join(cells))


def colmap_rows(folder: Path, truth: list[np.ndarray], mid: int, rng, repeats: int) -> list:
    """pycolmap.patch_match_stereo over ``folder/dense`` (every view), per-view wall time.

    Returns (name, wall s per view, cpu s per view, metrics of the middle view) rows; none
    where pycolmap has no CUDA.
    """
    import shutil

    import pycolmap

    from scenebot.dense.colmap_cuda import run_patch_match
    from scenebot.dense.colmap_io import read_array

    if not pycolmap.has_cuda:
        print("# --colmap: this pycolmap has no CUDA, no COLMAP row")
        return []
    dense = folder / "dense"
    names = sorted(p.name for p in (dense / "images").iterdir())
    cfg = DenseConfig(max_image_size=max(truth[0].shape), num_threads=-1)
    walls, cpus = [], []
    for _ in range(repeats + 1):  # the first run warms up CUDA
        for kind in ("depth_maps", "normal_maps", "consistency_graphs"):
            shutil.rmtree(dense / "stereo" / kind, ignore_errors=True)
            (dense / "stereo" / kind).mkdir(parents=True)
        c0 = time.process_time()
        walls.append(run_patch_match(cfg, dense, rng) / len(names))
        cpus.append((time.process_time() - c0) / len(names))
    depth = [read_array(dense / "stereo" / "depth_maps" / f"{n}.geometric.bin") for n in names]
    d = depth[mid]
    ms = [depth_map_metrics(x, g) for x, g in zip(depth, truth, strict=True)]
    print_per_view("colmap cuda", names, ms)
    return [(f"colmap cuda, {len(names)} views, per view", statistics.median(walls[1:]),
             statistics.median(cpus[1:]), depth_map_metrics(d, truth[mid]))]  # fmt: skip


def timed(fn, repeats: int):
    fn()  # warm-up (kernel compilation, caches)
    walls, cpus, out = [], [], None
    for _ in range(repeats):
        c0, w0 = time.process_time(), time.perf_counter()
        out = fn()
        walls.append(time.perf_counter() - w0)
        cpus.append(time.process_time() - c0)
    return statistics.median(walls), statistics.median(cpus), out


def stage_quality(width: int, height: int, out: str, backend: str, per_row: int) -> None:
    """Run the whole dense stage on a synthetic capture and print depth and cloud quality."""
    import shutil

    import open3d as o3d

    from scenebot.dense import evaluate, stage
    from scenebot.dense import workspace as ws
    from scenebot.dense.config import DenseConfig
    from scenebot.testing.dense import box_room_scene, make_dataset, stereo_rig

    root = Path(out)
    shutil.rmtree(root, ignore_errors=True)
    sc = box_room_scene()
    centers, headings = stereo_rig(num_per_row=per_row)
    rec, views = make_dataset(root / "capture", sc, centers, headings, width, height)
    cfg = DenseConfig(max_image_size=max(width, height), backend=backend)
    summary = stage.run(
        cfg,
        stage.DenseInputs(root / "capture" / "sparse", root / "capture" / "images"),
        stage.DenseOutputs(root / "dense"),
    )
    print(f"# dense stage, {len(views)} views {width}x{height}, backend {summary['backend']} "
          f"({summary['taichi_arch']}), load average {os.getloadavg()[0]:.1f}")  # fmt: skip
    print(f"{'view':14s} {'coverage':>9s} {'within 2%':>9s} {'photo s':>8s} {'geom s':>8s}")
    cov, acc = [], []
    for v, st in zip(views, summary["views"], strict=True):
        d, _ = ws.read_maps(root / "dense", v.name, "geometric")
        m = evaluate.depth_map_metrics(d, v.depth)
        cov.append(m["coverage"])
        acc.append(m["accuracy"])
        print(f"{v.name:14s} {m['coverage']:9.3f} {m['accuracy']:9.3f} "
              f"{st.get('photometric_s', float('nan')):8.2f} "
              f"{st.get('geometric_s', float('nan')):8.2f}")  # fmt: skip
    print(f"{'min / mean':14s} {min(cov):.3f}/{np.mean(cov):.3f} {min(acc):.3f}/{np.mean(acc):.3f}")
    K = rec.camera(1).calibration_matrix()
    cams = [(K, v.R, v.t, width, height) for v in views]
    ref = evaluate.visible_surface_samples(sc.vertices, sc.triangles, cams)
    pts = np.asarray(o3d.io.read_point_cloud(str(root / "dense" / "fused.ply")).points)
    metrics = evaluate.cloud_metrics(pts, sc.vertices, sc.triangles, ref)
    print(f"# fused cloud: {len(pts)} points; depth {summary['depth_seconds']:.1f} s, fusion "
          f"{summary['fusion_seconds']:.1f} s, total {summary['total_seconds']:.1f} s")  # fmt: skip
    print(f"{'tau':6s} {'accuracy':>9s} {'complete':>9s} {'F-score':>9s}")
    for tau in ("1cm", "2cm", "5cm"):
        m = metrics[tau]
        print(f"{tau:6s} {m['accuracy']:9.3f} {m['completeness']:9.3f} {m['fscore']:9.3f}")
    (root / "quality.json").write_text(json.dumps({"depth": [cov, acc], "cloud": metrics}))


#: the dense stage on a synthetic capture in a fresh process (argv: capture folder, output
#: folder, image size, num_threads); prints its summary's timings as JSON
_STAGE_SNIPPET = """
import json, sys
from pathlib import Path
from scenebot.dense import stage
from scenebot.dense.config import DenseConfig
cap, out, size, n = Path(sys.argv[1]), Path(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
cfg = DenseConfig(max_image_size=size, num_threads=n, taichi_arch="cpu", plots=False)
s = stage.run(cfg, stage.DenseInputs(cap / "sparse", cap / "images"), stage.DenseOutputs(out))
print(json.dumps({k: s[k] for k in ("processes", "depth_seconds", "fusion_seconds",
                                     "total_seconds")} | {"fill": s["plane_fill"]["seconds"]}))
"""


def stage_processes(
    root: Path, width: int, height: int, per_row: int, threads: tuple[int, ...], repeats: int
) -> dict[int, dict]:
    """The whole dense stage (taichi on the CPU) on one synthetic capture, once per entry of
    ``threads`` (``dense.num_threads``: worker processes), each in a fresh process, the
    settings interleaved over ``repeats`` rounds.

    Returns:
        Per num_threads: median ``wall_s``, ``cpu_s`` (the process and its workers),
        ``cpu_wall``, ``load`` (1-minute load average before its first run), the stage's
        last ``summary`` timings and ``metrics`` (mean coverage and within-2% accuracy of the
        final depth maps), and ``maps`` (the final depth maps, to compare the settings).
    """
    import resource
    import shutil
    import subprocess
    import sys

    from scenebot.dense import evaluate
    from scenebot.dense import workspace as ws
    from scenebot.testing.dense import box_room_scene, make_dataset, stereo_rig

    shutil.rmtree(root, ignore_errors=True)
    centers, headings = stereo_rig(num_per_row=per_row)
    _, views = make_dataset(root / "capture", box_room_scene(), centers, headings, width, height)
    runs: dict[int, dict] = {n: {"wall": [], "cpu": [], "load": None} for n in threads}
    for _ in range(repeats):
        for n in threads:
            out = root / f"dense_{n}"
            shutil.rmtree(out, ignore_errors=True)
            runs[n]["load"] = runs[n]["load"] or os.getloadavg()[0]
            r0, t0 = resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter()
            proc = subprocess.run(
                [sys.executable, "-c", _STAGE_SNIPPET, str(root / "capture"), str(out),
                 str(max(width, height)), str(n)],
                check=True, capture_output=True, text=True,
            )  # fmt: skip
            wall, r1 = time.perf_counter() - t0, resource.getrusage(resource.RUSAGE_CHILDREN)
            runs[n]["wall"].append(wall)
            runs[n]["cpu"].append(r1.ru_utime + r1.ru_stime - r0.ru_utime - r0.ru_stime)
            runs[n]["summary"] = json.loads(proc.stdout.strip().splitlines()[-1])
    result = {}
    for n, r in runs.items():
        maps = [ws.read_maps(root / f"dense_{n}", v.name, "geometric")[0] for v in views]
        ms = [evaluate.depth_map_metrics(d, v.depth) for d, v in zip(maps, views, strict=True)]
        wall, cpu = statistics.median(r["wall"]), statistics.median(r["cpu"])
        result[n] = {"wall_s": wall, "cpu_s": cpu, "cpu_wall": cpu / wall, "load": r["load"],
                     "summary": r["summary"], "maps": maps,
                     "metrics": {k: float(np.mean([m[k] for m in ms]))
                                 for k in ("coverage", "accuracy")}}  # fmt: skip
    return result


def print_stage_processes(result: dict[int, dict], num_views: int) -> None:
    """A table of :func:`stage_processes`: seconds per view, CPU/wall, quality."""
    first = result[min(result)]["maps"]
    print(f"{'num_threads':>11s} {'wall s':>8s} {'s/view':>7s} {'cpu s':>8s} {'cpu/wall':>8s} "
          f"{'load':>5s} {'coverage':>8s} {'within 2%':>9s} {'same maps':>9s}")  # fmt: skip
    for n, r in result.items():
        same = all(np.array_equal(a, b) for a, b in zip(first, r["maps"], strict=True))
        print(f"{n:11d} {r['wall_s']:8.1f} {r['wall_s'] / num_views:7.2f} {r['cpu_s']:8.1f} "
              f"{r['cpu_wall']:8.2f} {r['load']:5.1f} {r['metrics']['coverage']:8.3f} "
              f"{r['metrics']['accuracy']:9.3f} {same!s:>9s}")  # fmt: skip


def processes_main(args: argparse.Namespace) -> None:
    """``--processes``: the whole stage once per num_threads given, the table printed."""
    res = stage_processes(Path(args.out), args.width, args.height, args.per_row,
                          tuple(args.processes), args.repeats)  # fmt: skip
    print(f"# dense stage, {2 * args.per_row} synthetic views {args.width}x{args.height}, "
          f"taichi on the CPU, median of {args.repeats}")  # fmt: skip
    print_stage_processes(res, 2 * args.per_row)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=480)
    ap.add_argument("--sources", type=int, default=4, help="source views per reference")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--arch", default="cpu", choices=["cpu", "gpu", "auto"])
    ap.add_argument("--threads", type=int, default=2,
                    help="CPU threads of taichi and OpenCV (the plane sweep)")  # fmt: skip
    ap.add_argument("--skip-reference", action="store_true")
    ap.add_argument("--all-views", action="store_true",
                    help="also time the stage's passes over every view, per view")  # fmt: skip
    ap.add_argument("--export", type=Path, help="write the views as a COLMAP workspace + npz")
    ap.add_argument("--views", type=Path, help="read the views from an --export npz")
    ap.add_argument("--colmap", type=Path,
                    help="an --export folder: also run pycolmap's CUDA PatchMatch")  # fmt: skip
    ap.add_argument("--no-taichi", action="store_true",
                    help="with --colmap: the COLMAP row alone, no taichi import")  # fmt: skip
    ap.add_argument("--json", type=Path, help="write the rows and settings here")
    ap.add_argument("--stage", action="store_true", help="run the whole stage, print quality")
    ap.add_argument("--backend", default="auto", choices=["auto", "taichi", "colmap_cuda"])
    ap.add_argument("--per-row", type=int, default=7, help="--stage: cameras per row (2 rows)")
    ap.add_argument("--out", default="benchmarks/out/dense_stage", help="--stage: output folder")
    ap.add_argument("--processes", type=int, nargs="*",
                    help="the whole stage (CPU) once per dense.num_threads given (e.g. 1 2), "
                    "interleaved over --repeats, in --out")  # fmt: skip
    args = ap.parse_args()
    if args.processes:
        return processes_main(args)
    if args.no_taichi:  # COLMAP alone: no taichi needed (a machine with the CUDA pycolmap)
        if not args.colmap:
            ap.error("--no-taichi needs --colmap")
        truth = list(np.load(args.colmap / "views.npz")["depth"])
        for name, wall, cpu, m in colmap_rows(args.colmap, truth, (len(truth) - 1) // 2,
                                              (0.5, 4.5), args.repeats):  # fmt: skip
            print(f"{name}: {wall:.3f} s wall, {cpu:.3f} s cpu per view; middle view "
                  f"coverage {m['coverage']:.3f}, within 2% {m['accuracy']:.3f}")  # fmt: skip
            if args.json:
                args.json.write_text(json.dumps({"name": name, "wall_s": wall, "cpu_s": cpu, **m}))
        return
    from scenebot.dense.patchmatch import PatchMatchSolver
    from scenebot.taichi_setup import init_taichi

    if args.stage:
        init_taichi(args.arch, args.threads)
        stage_quality(args.width, args.height, args.out, args.backend, args.per_row)
        return

    if args.arch == "cpu":
        cv2.setNumThreads(args.threads)
    n = args.sources + 1
    if args.views:
        views, truth = load_views(args.views)
    elif args.export:
        views, truth = export_views(args.export, args.width, args.height, n)
    else:
        views, truth = make_views(args.width, args.height, n)
    h, w = views[0].gray.shape
    mid = (len(views) - 1) // 2
    ref, gt = views[mid], truth[mid]
    srcs = [v for i, v in enumerate(views) if i != mid]
    cfg = PatchMatchConfig()
    rng = (0.5, 4.5)
    rows = []
    ref_wall = None
    if not args.skip_reference:
        wall, cpu, d = timed(lambda: plane_sweep(ref, srcs, rng), args.repeats)
        ref_wall = wall
        rows.append(("plane-sweep (ref), 96 planes", wall, cpu, depth_map_metrics(d, gt)))
    arch = init_taichi(args.arch, args.threads)
    rows += taichi_rows(PatchMatchSolver(cfg), views, truth, mid, rng, args.repeats, arch,
                        args.all_views)  # fmt: skip
    if args.colmap:
        rows += colmap_rows(args.colmap, truth, mid, rng, args.repeats)

    iters = "/".join(str(i) for i in cfg.iterations)
    print(
        f"# {w}x{h}, {len(srcs)} source views, top_k={cfg.top_k}, "
        f"iterations per level (full res first) {iters}, neighbours {cfg.neighbors}, "
        f"geom iterations {cfg.geom_iterations}, window {2 * cfg.window_radius + 1}px step "
        f"{cfg.window_step}, taichi arch {arch}, threads {args.threads}, "
        f"load average {os.getloadavg()[0]:.1f}, median of {args.repeats}"
    )
    print(f"{'method':44s} {'wall s':>8s} {'cpu s':>8s} {'ref/this':>9s} {'coverage':>9s} "
          f"{'within 2%':>9s}")  # fmt: skip
    for name, wall, cpu, m in rows:
        ratio = ref_wall / wall if ref_wall else float("nan")
        print(f"{name:44s} {wall:8.3f} {cpu:8.3f} {ratio:9.2f} {m['coverage']:9.3f} "
              f"{m['accuracy']:9.3f}")  # fmt: skip
    if args.json:
        args.json.write_text(json.dumps({
            "size": [w, h], "sources": len(srcs), "arch": arch, "threads": args.threads,
            "repeats": args.repeats, "iterations": list(cfg.iterations),
            "geom_iterations": cfg.geom_iterations,
            "rows": [{"name": r[0], "wall_s": r[1], "cpu_s": r[2], **r[3]} for r in rows],
        }, indent=1))  # fmt: skip


def taichi_rows(solver, views, truth, mid, rng, repeats, arch, all_views) -> list:
    """Photometric, full (photometric + geometric + filter) for the middle view and, with
    ``all_views``, the stage's three passes over every view (per view)."""
    ref, gt = views[mid], truth[mid]
    srcs = [v for i, v in enumerate(views) if i != mid]
    rows = []

    def photometric():
        return solver.estimate(ref, srcs, rng)

    photometric()
    # the geometric pass reads the sources' own photometric depth maps, as in the stage
    src_photo = [solver.estimate(v, [x for x in views if x is not v], rng).depth for v in srcs]

    def full():
        p = solver.estimate(ref, srcs, rng)
        g = solver.estimate(ref, srcs, rng, src_depths=src_photo, init=(p.depth, p.normal))
        return solver.filter(ref, srcs, g, src_photo)

    wall, cpu, r = timed(photometric, repeats)
    rows.append((f"taichi photometric [{arch}]", wall, cpu, depth_map_metrics(r.depth, gt)))
    wall, cpu, r = timed(full, repeats)
    rows.append((f"taichi photo+geom+filter [{arch}]", wall, cpu, depth_map_metrics(r.depth, gt)))
    if all_views:

        def stage_passes():
            others = [[x for x in views if x is not v] for v in views]
            ph = [solver.estimate(v, o, rng) for v, o in zip(views, others, strict=True)]
            ge = [solver.estimate(v, o, rng, init=(p.depth, p.normal),
                                  src_depths=[q.depth for q in ph if q is not p])
                  for v, o, p in zip(views, others, ph, strict=True)]  # fmt: skip
            return [solver.filter(v, o, g, [q.depth for q in ge if q is not g])
                    for v, o, g in zip(views, others, ge, strict=True)]  # fmt: skip

        wall, cpu, out = timed(stage_passes, repeats)
        ms = [depth_map_metrics(o.depth, g) for o, g in zip(out, truth, strict=True)]
        print_per_view("taichi all views", [v.name for v in views], ms)
        rows.append((f"taichi all {len(views)} views, per view [{arch}]", wall / len(views),
                     cpu / len(views), ms[mid]))  # fmt: skip
    return rows


if __name__ == "__main__":
    main()
