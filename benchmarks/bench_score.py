"""Speed and accuracy of the rendering-quality score: taichi kernel vs the numpy reference.

Scene: a synthetic 6 m x 4 m office (two furniture boxes) mapped by photo rings (12 photos per
position) at random free positions; the mesh is the Poisson surface of 12,000 sampled points
seen by those photos (the real mesh stage), decimated to ``score.max_triangles``; candidates
are drawn in its free space as the score stage does. All rates are candidate evaluations per
second (median of repeats, wall clock), measured in this run for both implementations; the
"cpu" columns divide by the process CPU time instead (robust to other load on the machine:
evals per CPU-second, i.e. per core); "load" is the 1-minute load average when a figure's
timed runs began and "cpu/wall" the process CPU time / wall time over them (about the cores
in use: a figure compares with another run's only where these agree). Run:

    TI_SKIP_VERSION_CHECK=ON nice -n 10 .venv/bin/python benchmarks/bench_score.py [--quick]

``--export FILE.npz`` saves the decimated mesh, the source poses and the candidates (and stops);
``--scene
FILE.npz --arch gpu --no-reference`` times the taichi kernel on them where open3d (mesh
building, the numpy reference's ray casting) is not installed, e.g. on a GPU machine.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")

from scenebot.artifacts.mesh import decimate
from scenebot.geometry import Intrinsics, read_sparse_map
from scenebot.mesh.config import MeshConfig
from scenebot.mesh.freespace import compute_freespace
from scenebot.mesh.poisson import build_mesh
from scenebot.score.candidates import sample_candidates
from scenebot.score.config import ScoreConfig
from scenebot.score.kernel import TaichiScorer, init_taichi, source_views_for_depth
from scenebot.score.reference import ReferenceScorer
from scenebot.testing import score as syn

RESOLUTIONS = [(40, 30), (80, 60), (160, 120)]
SOURCES = [25, 100, 400]


def ring_positions(n_rings: int, rng: np.random.Generator) -> np.ndarray:
    """Random photo-ring positions in the room, outside the furniture (m)."""
    out = []
    while len(out) < n_rings:
        x, y = rng.uniform(-2.4, 2.4), rng.uniform(-1.5, 1.5)
        in_table = 0.9 < x < 2.5 and 0.3 < y < 1.7
        in_cabinet = x < -1.6 and y < -1.0
        if not (in_table or in_cabinet):
            out.append((x, y))
    return np.array(out)


def build_scene(rng: np.random.Generator):
    """Mesh (from the mesh stage) and all 400 source poses of the benchmark room."""
    V, F = syn.room(cell_m=0.5)
    R, t, _ = syn.ring_sources(ring_positions(34, rng), 12)
    R, t = R[: max(SOURCES)], t[: max(SOURCES)]
    K = syn.default_intrinsics()
    pts, _ = syn.sample_surface(V, F, 12000, rng)
    with tempfile.TemporaryDirectory() as tmp:
        sfm = Path(tmp) / "round_001" / "sfm"
        syn.write_colmap_model(
            sfm, K, R[:100], t[:100], pts, syn.visible_mask(V, F, R[:100], t[:100], K, pts), rng
        )
        smap = read_sparse_map(sfm)
    Vm, Fm = build_mesh(smap.xyz, smap.view_dir, smap.track_len, MeshConfig(), "bench")
    cfg = MeshConfig()
    fs = compute_freespace(
        Vm,
        Fm,
        smap.centres[:, :2],
        cfg.robot_radius_m,
        cfg.cut_heights_m,
        cfg.grid_resolution_m,
        "bench",
    )
    return Vm, Fm, R, t, K, fs


def rate(fn, n: int, repeats: int) -> tuple[float, float, float, float]:
    """Median wall and CPU evaluation rates (evals/s) of ``fn()`` which scores ``n`` views,
    the 1-minute load average before the first call, and the median CPU time / wall time
    (about the number of cores in use: compare runs only where these agree)."""
    walls, cpus, ratios = [], [], []
    load = os.getloadavg()[0]
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall, cpu = time.perf_counter() - t0, max(time.process_time() - c0, 1e-9)
        walls.append(n / wall)
        cpus.append(n / cpu)
        ratios.append(cpu / wall)
    return statistics.median(walls), statistics.median(cpus), load, statistics.median(ratios)


def scorers(V, F, R, t, K, w, h, S, batch, backend="cpu", reference=True, kernel=None):
    """Taichi scorer (of ``kernel``, a module such as :func:`kernel_at` returns, default the
    current one) and numpy reference scorer for the first S sources at w x h."""
    cfg = ScoreConfig()
    sv, size = source_views_for_depth(R[:S], t[:S], [K] * S, cfg.source_depth_width)
    intr = K.scaled(w, h)
    common = {"depth_tolerance": cfg.depth_tolerance, "near_m": cfg.near_m}
    cls = TaichiScorer if kernel is None else kernel.TaichiScorer
    tk = cls(V, F, sv, size, intr, batch_size=batch, backend=backend, **common)
    ref = ReferenceScorer(V, F, sv, size, intr, **common) if reference else None
    return tk, ref


def kernel_at(rev: str):
    """The score kernel (``scenebot/score/kernel.py`` and ``_tikernels.py``) of git revision
    ``rev``, imported beside the current one, so that both are timed in the same process.

    The files are written to a temporary package whose ``kernel`` imports its own
    ``_tikernels``; it shares the taichi runtime that :func:`init_taichi` started (call that
    and build the current scorer first).
    """
    import importlib
    import subprocess
    import sys

    import scenebot.score.kernel as current

    root = Path(__file__).resolve().parent.parent
    safe = "".join(c if c.isalnum() else "_" for c in rev)
    pkg = f"score_kernel_{safe}"
    if pkg + ".kernel" in sys.modules:
        return sys.modules[pkg + ".kernel"]
    folder = Path(tempfile.mkdtemp(prefix="scenebot_kernel_")) / pkg
    folder.mkdir()
    (folder / "__init__.py").write_text("")
    for name in ("_tikernels.py", "kernel.py"):
        text = subprocess.run(
            ["git", "-C", str(root), "show", f"{rev}:scenebot/score/{name}"],
            capture_output=True, text=True, check=True,
        ).stdout  # fmt: skip
        own = f"from {pkg} import _tikernels"
        text = text.replace("from scenebot.score import _tikernels", own)
        (folder / name).write_text(text)
    sys.path.insert(0, str(folder.parent))
    mod = importlib.import_module(pkg + ".kernel")
    mod._TI_STATE.update(current._TI_STATE)  # the running taichi: do not start it again
    return mod


def save_scene(path: Path, V, F, R, t, K: Intrinsics, cands: np.ndarray) -> None:
    """The scoring inputs (decimated mesh, sources, candidates) for ``--scene``."""
    k = [K.width, K.height, K.fx, K.fy, K.cx, K.cy]
    np.savez_compressed(path, V=V, F=F, R=R, t=t, K=np.array(k, float), cands=cands)


def load_scene(path: Path):
    """(V, F, R, t, K, candidates) written by :func:`save_scene`."""
    z = np.load(path)
    w, h, fx, fy, cx, cy = z["K"]
    K = Intrinsics(int(w), int(h), float(fx), float(fy), float(cx), float(cy))
    return z["V"], z["F"], z["R"], z["t"], K, z["cands"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer candidates and repeats")
    ap.add_argument("--arch", default="cpu", choices=["cpu", "gpu"], help="taichi arch")
    ap.add_argument("--export", type=Path, help="save the scoring inputs to this .npz")
    ap.add_argument("--scene", type=Path, help="score the inputs of an --export .npz")
    ap.add_argument("--no-reference", action="store_true", help="taichi rates only")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    arch = init_taichi(args.arch)
    print(f"taichi arch: {arch}; CPU cores: {os.cpu_count()}; load avg: {os.getloadavg()}")
    n_tk = 500 if args.quick else 2000
    reps = 3 if args.quick else 5
    cfg = ScoreConfig()
    if args.scene:
        V, F, R, t, K, cands = load_scene(args.scene)
        V0 = F0 = None
        print(f"scene: {args.scene}, {len(F)} triangles, {len(cands)} candidates\n")
    else:
        t0 = time.perf_counter()
        V0, F0, R, t, K, fs = build_scene(rng)
        print(
            f"scene: mesh {len(F0)} triangles, free space {fs.area_m2:.1f} m^2 "
            f"(built in {time.perf_counter() - t0:.1f} s)"
        )
        cands = sample_candidates(fs, n_tk, rng, "bench")
        V, F = decimate(V0, F0, cfg.max_triangles)
        print(f"scoring mesh: decimated to {len(F)} triangles (score.max_triangles)\n")
        if args.export:
            save_scene(args.export, V, F, R, t, K, cands)
            print(f"written {args.export}")
            return

    # --- scaling table (includes the acceptance point 80x60, 100 sources) -------------------
    head = (
        f"{'res':>8} {'src':>4} | {'taichi/s':>9} {'cpu/s':>8} {'load':>5} {'cpu/wall':>8} "
        f"| {'numpy/s':>8} {'cpu/s':>7} {'load':>5} {'cpu/wall':>8} "
        f"| {'ratio':>6} {'cpu ratio':>9} | {'mean|d|deg':>10} {'max|d|':>7}"
    )
    print(head)
    print("-" * len(head))
    for w, h in RESOLUTIONS:
        for S in SOURCES:
            tk, ref = scorers(V, F, R, t, K, w, h, S, cfg.batch_size, args.arch,
                              not args.no_reference)  # fmt: skip
            tk.score(cands[: cfg.batch_size])  # compile
            n = n_tk if (w * h * S) <= 80 * 60 * 100 else n_tk // 2
            tw, tc, tl, tr = rate(lambda n=n, tk=tk: tk.score(cands[:n]), n, reps)
            if ref is None:
                print(f"{w:>4}x{h:<3} {S:>4} | {tw:9.0f} {tc:8.0f} {tl:5.2f} {tr:8.2f} |")
                continue
            # the reference on a subset sized to ~2 s of work at ~40 evals/s for 80x60/100
            m = int(np.clip(80 * (80 * 60 * 100) / (w * h * S), 4, 120))
            if args.quick:
                m = max(4, m // 3)
            nw, nc, nl, nr = rate(lambda m=m, ref=ref: ref.score(cands[:m]), m, 3)
            a = tk.score(cands[:m]).score_deg
            b = ref.score(cands[:m]).score_deg
            d = np.abs(a - b)
            print(
                f"{w:>4}x{h:<3} {S:>4} | {tw:9.0f} {tc:8.0f} {tl:5.2f} {tr:8.2f} "
                f"| {nw:8.1f} {nc:7.1f} {nl:5.2f} {nr:8.2f} "
                f"| {tw / nw:6.1f} {tc / nc:9.1f} | {np.nanmean(d):10.4f} {np.nanmax(d):7.3f}"
            )
    if V0 is None:
        return

    # --- decimation: scores on a decimated mesh against the full mesh (taichi, 80x60) ------
    print(
        f"\ndecimation (80x60, 100 sources, {min(n_tk, 1000)} candidates; "
        "difference to the full-mesh scores)"
    )
    head2 = f"{'triangles':>9} | {'taichi/s':>9} {'cpu/s':>8} {'load':>5} {'cpu/wall':>8} | "
    head2 += f"{'mean|d|deg':>10} {'p95':>7} {'max':>7}"
    print(head2)
    print("-" * len(head2))
    full = None
    nd = min(n_tk, 1000)
    for n_tri in (0, 20000, 10000, 5000, 2500):
        Vd, Fd = decimate(V0, F0, n_tri)
        sv, size = source_views_for_depth(R[:100], t[:100], [K] * 100, cfg.source_depth_width)
        tk = TaichiScorer(
            Vd,
            Fd,
            sv,
            size,
            K.scaled(80, 60),
            depth_tolerance=cfg.depth_tolerance,
            near_m=cfg.near_m,
            batch_size=cfg.batch_size,
            backend=args.arch,
        )
        tk.score(cands[: cfg.batch_size])
        s = tk.score(cands[:nd]).score_deg
        tw, tc, tl, tr = rate(lambda tk=tk: tk.score(cands[:nd]), nd, max(2, reps - 2))
        if full is None:
            full = s
        d = np.abs(s - full)
        print(
            f"{len(Fd):>9} | {tw:9.0f} {tc:8.0f} {tl:5.2f} {tr:8.2f} | {np.nanmean(d):10.4f} "
            f"{np.nanpercentile(d, 95):7.3f} {np.nanmax(d):7.3f}"
        )
    print(f"\nload avg at the end: {os.getloadavg()}")


if __name__ == "__main__":
    main()
