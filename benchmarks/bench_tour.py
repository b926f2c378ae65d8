"""Speed of the tour renderer: seconds per 640x480 frame and a full 300-frame tour.

On the campaign's last map (default ``results/office``: round_000 model, photos, dense cloud),
along the stage's own tour path. Rows (median wall time per frame over ``--repeats`` passes
over ``--sample`` frames, after one warm-up frame that compiles the kernels):

* reference: the ULR kernel evaluating every photo at every pixel (no preselection);
* the proxy depth alone: splatting, clean-up and hole filling (part of every frame);
* one ULR frame as the stage renders it (per-frame source preselection);
* with ``--full``: the whole stage for ``--frames`` frames (load, path, frames, JPEGs, H.264
  video, viewer; no evaluation), one run, against frames x the reference frame.

Ratios are figure / reference (< 1 = faster). ``bench(quick)`` gives the rows to
``benchmarks/run.py``. Run ``python benchmarks/bench_tour.py --help``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")

import numpy as np


def measure(
    scene: Path = Path("results/office"),
    round_: str = "000",
    width: int = 640,
    height: int = 480,
    frames: int = 300,
    sample: int = 8,
    repeats: int = 3,
    arch: str = "cpu",
    threads: int = -1,
    full: bool = False,
    echo: bool = True,
) -> list[dict]:
    """Time the renderer (and with ``full`` the whole stage); rows in benchmarks/run.py form."""
    from scenebot.tour.config import TourConfig
    from scenebot.tour.stage import (
        TourInputs,
        TourOutputs,
        build_renderer,
        plan_valid_path,
        run,
        tour_camera,
    )

    inputs = TourInputs(
        scene / f"round_{round_}" / "sfm",
        scene,
        scene / "final" / "dense" / "fused.ply",
        scene / f"round_{round_}" / "freespace.npz",
    )
    cfg = TourConfig.model_validate(
        {
            "width": width,
            "height": height,
            "taichi_arch": arch,
            "num_threads": threads,
            "eval_holdout": 0,
            "path": {"frames": frames},
        }
    )
    t0 = time.perf_counter()
    renderer, arch_name = build_renderer(cfg, inputs)
    load_s = time.perf_counter() - t0
    path = plan_valid_path(cfg, renderer, inputs.freespace_npz)
    cam = tour_camera(cfg, renderer.sources[0].camera)
    idx = np.unique(np.linspace(0, len(path) - 1, sample).round().astype(int))
    if echo:
        print(
            f"scene {scene}: {renderer.num_sources} photos, {len(renderer.proxy)} proxy points, "
            f"{cam.width}x{cam.height}, taichi {arch_name}, load {load_s:.1f} s, "
            f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}"
        )

    def timed(fn) -> float:
        fn(int(idx[0]))  # warm-up (kernel compilation)
        reps = []
        for _ in range(repeats):
            t = time.perf_counter()
            for i in idx:
                fn(int(i))
            reps.append((time.perf_counter() - t) / len(idx))
        return statistics.median(reps)

    def ulr_all(i):
        old = renderer.cfg.ulr.max_sources
        renderer.cfg.ulr.max_sources = 0
        try:
            renderer.render(cam, *path.pose(i))
        finally:
            renderer.cfg.ulr.max_sources = old

    ref_name = "ULR kernel over all sources per pixel"
    ref = timed(ulr_all)
    size = f"{cam.width}x{cam.height}, {renderer.num_sources} photos"
    rows = [
        {
            "group": "tour",
            "name": f"proxy depth of one frame (splats + hole filling), {size}",
            "median": 1000 * timed(lambda i: renderer.splatter.depth(cam, *path.pose(i))),
            "unit": "ms",
            "repeats": repeats,
            "reference": ref_name,
            "reference_median": 1000 * ref,
        },
        {
            "group": "tour",
            "name": f"one ULR frame as the stage renders it, {size}",
            "median": 1000 * timed(lambda i: renderer.render(cam, *path.pose(i))),
            "unit": "ms",
            "repeats": repeats,
            "reference": ref_name,
            "reference_median": 1000 * ref,
        },
    ]
    if full:
        with tempfile.TemporaryDirectory() as tmp:
            t = time.perf_counter()
            summary = run(cfg, inputs, TourOutputs(Path(tmp) / "tour"), progress=False)
            total = time.perf_counter() - t
        rows.append(
            {
                "group": "tour",
                "name": f"whole tour stage, {summary['frames']} frames {size} (+ video, viewer)",
                "median": total,
                "unit": "s",
                "repeats": 1,
                "reference": f"{summary['frames']} x the all-sources ULR frame",
                "reference_median": summary["frames"] * ref,
                "note": f"render {summary['render_s']:.1f} s, codec {summary['video_codec']}",
            }
        )
    if echo:
        print(f"{'figure':<78}{'median':>10}{'ratio':>8}")
        print(f"{'reference: ' + ref_name:<78}{1000 * ref:>8.1f}ms{1.0:>8.2f}")
        for r in rows:
            ratio = r["median"] / r["reference_median"]
            print(f"{r['name']:<78}{r['median']:>8.1f}{r['unit']:>2}{ratio:>8.2f}")
    return rows


def bench(quick: bool) -> list[dict]:
    """Rows for benchmarks/run.py (needs the campaign's results/office)."""
    scene = Path(__file__).resolve().parents[1] / "results" / "office"
    if not (scene / "final" / "dense" / "fused.ply").is_file():
        return []  # run the campaign first (make demo)
    if quick:
        return measure(scene, frames=60, sample=4, repeats=2, echo=False)
    return measure(scene, full=True, echo=False)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene-dir", default="results/office", type=Path)
    ap.add_argument("--round", default="000")
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=480)
    ap.add_argument("--frames", type=int, default=300, help="frames of the full stage run")
    ap.add_argument("--sample", type=int, default=8, help="frames timed per repeat")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--arch", default="cpu", choices=["cpu", "gpu", "auto"])
    ap.add_argument("--threads", type=int, default=-1)
    ap.add_argument("--full", action="store_true", help="also time the whole stage")
    a = ap.parse_args()
    measure(
        a.scene_dir, a.round, a.width, a.height, a.frames, a.sample, a.repeats, a.arch,
        a.threads, a.full,
    )  # fmt: skip


if __name__ == "__main__":
    main()
