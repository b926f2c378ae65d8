"""Speed and quality of the dense depth estimation on synthetic 640x480 views.

Compares, on the same reference view and sources (true cameras, known depth):

* ``plane-sweep (ref)``: a numpy/OpenCV fronto-parallel plane sweep with box-filtered NCC and
  top-k source aggregation (the kind of prototype the issue measured), the same-run reference;
* ``taichi photometric``: the PatchMatch photometric pass (coarse-to-fine);
* ``taichi full``: photometric + geometric pass + filter (what the stage runs per view);
* ``colmap cuda``: pycolmap.patch_match_stereo on the same views, only where pycolmap has CUDA.

Each row: median wall time over repeats (after one warm-up that compiles the kernels), median
process CPU time, the ratio to the reference, and quality: coverage (fraction of pixels with a
depth; the unfiltered passes give every pixel one) and accuracy (fraction of those within 2 % of
the true depth). Run ``python benchmarks/bench_dense.py --help``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")

import cv2
import numpy as np

from scenebot.dense.config import PatchMatchConfig
from scenebot.dense.evaluate import depth_map_metrics
from scenebot.dense.patchmatch import PatchMatchSolver, StereoView, init_taichi
from scenebot.dense.synthetic import box_room_scene, intrinsics, look_at_pose, render_view


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


def make_views(width: int, height: int, num: int) -> tuple[list[StereoView], list[np.ndarray]]:
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
    import json
    import shutil
    from pathlib import Path

    import open3d as o3d

    from scenebot.dense import evaluate, stage
    from scenebot.dense import workspace as ws
    from scenebot.dense.config import DenseConfig
    from scenebot.dense.synthetic import make_dataset, stereo_rig

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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=480)
    ap.add_argument("--sources", type=int, default=4, help="source views per reference")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--arch", default="cpu", choices=["cpu", "gpu", "auto"])
    ap.add_argument("--threads", type=int, default=2, help="taichi CPU threads")
    ap.add_argument("--skip-reference", action="store_true")
    ap.add_argument("--stage", action="store_true", help="run the whole stage, print quality")
    ap.add_argument("--backend", default="auto", choices=["auto", "taichi", "colmap_cuda"])
    ap.add_argument("--per-row", type=int, default=7, help="--stage: cameras per row (2 rows)")
    ap.add_argument("--out", default="benchmarks/out/dense_stage", help="--stage: output folder")
    args = ap.parse_args()
    if args.stage:
        init_taichi(args.arch, args.threads)
        stage_quality(args.width, args.height, args.out, args.backend, args.per_row)
        return

    arch = init_taichi(args.arch, args.threads)
    views, truth = make_views(args.width, args.height, args.sources + 1)
    mid = args.sources // 2
    ref, gt = views[mid], truth[mid]
    srcs = [v for i, v in enumerate(views) if i != mid]
    src_gt = [d for i, d in enumerate(truth) if i != mid]
    cfg = PatchMatchConfig()
    solver = PatchMatchSolver(cfg)
    rng = (0.5, 4.5)

    def photometric():
        return solver.estimate(ref, srcs, rng)

    photometric()
    # the geometric pass reads the sources' own photometric depth maps, as in the stage
    src_photo = [solver.estimate(v, [w for w in views if w is not v], rng).depth for v in srcs]

    def full():
        p = solver.estimate(ref, srcs, rng)
        g = solver.estimate(ref, srcs, rng, src_depths=src_photo, init=(p.depth, p.normal))
        return solver.filter(ref, srcs, g, src_photo)

    rows = []
    ref_wall = None
    if not args.skip_reference:
        wall, cpu, d = timed(lambda: plane_sweep(ref, srcs, rng), args.repeats)
        ref_wall = wall
        rows.append(("plane-sweep (ref), 96 planes", wall, cpu, depth_map_metrics(d, gt)))
    wall, cpu, r = timed(photometric, args.repeats)
    rows.append((f"taichi photometric [{arch}]", wall, cpu, depth_map_metrics(r.depth, gt)))
    wall, cpu, r = timed(full, args.repeats)
    rows.append((f"taichi photo+geom+filter [{arch}]", wall, cpu, depth_map_metrics(r.depth, gt)))

    import pycolmap

    if pycolmap.has_cuda:
        print("# pycolmap has CUDA: compare with `--stage --backend colmap_cuda`")
    _ = src_gt
    iters = "/".join(str(i) for i in cfg.iterations)
    print(
        f"# {args.width}x{args.height}, {len(srcs)} source views, top_k={cfg.top_k}, "
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


if __name__ == "__main__":
    main()
