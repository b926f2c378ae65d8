"""Visual localization in the simulated office: accuracy and speed, DLT (paper) vs pycolmap.

Map: reference photos rendered by the simulator on circles at free spots (like round-0
exploration), every SIFT keypoint back-projected with the renderer's true depth, points merged
on a 1 cm lattice (several descriptors per point). This map has no SfM error, so the accuracy
figures isolate the localization itself. Methods: ``dlt`` (the paper's RANSAC + DLT + RQ +
refinement, focal length fixed to the map camera's, the default), ``dlt+f`` (also refining f,
exactly as the paper) and ``pycolmap`` (P3P LO-RANSAC + refinement); ``o0``: query SIFT with
first_octave 0 (the map keeps -1). ``ok``: photos localized
(>= min_inliers); ``>25cm``: of those, gross errors. Queries: photos (with the simulator's
image noise) at random free poses and headings; errors are camera-centre distance (cm, also
in inches) and heading (deg) against the simulator's truth (evaluation only).

Speed: SIFT extraction at 640x480 (pycolmap, first_octave -1 and 0); FLANN matching of 1,000
query descriptors against a 160,000-row map (the office map's real descriptors, each repeated
with noise as further observations until 160k rows); same-run reference: exact brute force
(OpenCV BFMatcher) on the same data, with the FLANN recall of the exact nearest neighbour's
3D point.

    .venv/bin/python benchmarks/bench_localize.py [--spots 4] [--headings 12] [--queries 30]
        [--follow 10]

``--sfm DIR --capture DIR``: accuracy on a real map of the sfm stage (round_000/sfm) of a
simulated capture (its log.jsonl has the true poses): query photos are rendered at random
free poses in the same office, localized in the map frame, and mapped into the world frame by
the similarity that best aligns the map's camera centres with their true centres (evaluation
only, as in the paper's Fig. 5 experiment).

``--follow N``: path following in the office with this visual localization (SimRobot physics
with slip and bumpers, PathFollower, planner on points sampled from the scene's surfaces as a
stand-in for the sparse map): N chained random reachable goals, reached within 10 cm (truth)?

The map is cached in benchmarks/out/. Figures are medians over repeats.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import cv2
import numpy as np
import pycolmap

from scenebot.config import SimConfig
from scenebot.localize import LocalizationMap, LocalizeConfig, localize
from scenebot.localize.features import extract_sift, load_gray
from scenebot.localize.index import DescriptorIndex, MapDescriptors
from scenebot.localize.match import match_to_map
from scenebot.scene.office import office
from scenebot.sim.renderer import look_rotation
from scenebot.sim.world import SimWorld

OUT = Path(__file__).resolve().parent / "out"


def free_spot(world: SimWorld, rng: np.random.Generator, clearance: float) -> np.ndarray:
    lo, hi = world.scene.bounds
    while True:
        xy = rng.uniform(lo[:2] + 0.3, hi[:2] - 0.3)
        if world.collision_map.clearance_at(xy) > clearance:
            return xy


def camera_at(world: SimWorld, xy: np.ndarray, heading: float):
    cam = world.cfg.camera
    c = np.array(
        [
            xy[0] + cam.forward_offset_m * math.cos(heading),
            xy[1] + cam.forward_offset_m * math.sin(heading),
            world.scene.floor_z + cam.height_m,
        ]
    )
    return look_rotation(heading), c


def build_office_map(world: SimWorld, spots: int, headings: int, seed: int = 0) -> MapDescriptors:
    cache = OUT / f"office_map_s{spots}_h{headings}_seed{seed}.npz"
    if cache.exists():
        with np.load(cache) as z:
            return MapDescriptors(z["point_ids"], z["xyz"], z["descriptors"])
    rng = np.random.default_rng(seed)
    intr = world.intrinsics
    loc = LocalizeConfig()
    xyz, desc = [], []
    for _ in range(spots):
        xy = free_spot(world, rng, 0.5)
        for th in np.arange(headings) * 2 * math.pi / headings:
            R, c = camera_at(world, xy, th)
            img, depth = world.renderer.render(intr, R, c, rng, return_depth=True)
            # the map's SIFT: COLMAP's first octave (-1), as the sfm stage extracts it
            kps, d = extract_sift(load_gray(img), -1, loc.sift_max_features, loc.sift_num_threads)
            ij = np.clip(kps.astype(int), 0, [intr.width - 1, intr.height - 1])
            z = np.asarray(depth)[ij[:, 1], ij[:, 0]]
            ok = np.isfinite(z) & (z > 0)
            ray = np.c_[(kps[ok] - [intr.cx, intr.cy]) / [intr.fx, intr.fy], np.ones(ok.sum())]
            xyz.append((ray * z[ok, None]) @ R + c)
            desc.append(d[ok])
    X = np.concatenate(xyz)
    _, ids = np.unique(np.floor(X / 0.01).astype(np.int64), axis=0, return_inverse=True)
    ids = ids.ravel().astype(np.int64)
    n = ids.max() + 1
    mean = np.zeros((n, 3))
    np.add.at(mean, ids, X)
    mean /= np.bincount(ids, minlength=n)[:, None]
    md = MapDescriptors(ids, mean[ids], np.concatenate(desc))
    OUT.mkdir(parents=True, exist_ok=True)
    np.savez(cache, point_ids=md.point_ids, xyz=md.xyz, descriptors=md.descriptors)
    return md


def pct(v, q):
    return float(np.percentile(v, q)) if len(v) else float("nan")


def accuracy(world, md, cam, queries: int, seed: int = 1, check_pose: bool = True) -> None:
    rng = np.random.default_rng(seed)
    poses = [(free_spot(world, rng, 0.3), rng.uniform(0, 2 * math.pi)) for _ in range(queries)]
    photos = []
    for xy, th in poses:
        R, c = camera_at(world, xy, th)
        photos.append((world.renderer.render(world.intrinsics, R, c, rng), R, c, th))
    print(
        f"\naccuracy: {queries} query photos at random free poses (office map, true depth);"
        f" level-camera check {'on' if check_pose else 'off'}"
    )
    print(
        f"{'method':>9} {'ok':>6} {'>25cm':>5} {'med cm':>7} {'p90 cm':>7} {'med in':>7}"
        f" {'p90 in':>7} {'med deg':>8} {'p90 deg':>8} {'inliers':>8} {'extract':>8}"
        f" {'match':>7} {'pose':>7} {'total ms':>8}"
    )
    # this map is in the world frame: the camera plane is at the camera height, not z = 0
    plane = {"camera_plane_z_m": world.scene.floor_z + world.cfg.camera.height_m}
    if not check_pose:
        plane = {"camera_plane_z_m": None, "camera_pitch_deg": None}
    variants = {
        "dlt": LocalizeConfig(method="dlt", sift_first_octave=-1, **plane),
        "dlt+f": LocalizeConfig(method="dlt", refine_focal=True, sift_first_octave=-1, **plane),
        "pycolmap": LocalizeConfig(method="pycolmap", sift_first_octave=-1, **plane),
    }
    if check_pose:  # the faster extraction: no upsampled first octave
        variants["dlt o0"] = LocalizeConfig(method="dlt", sift_first_octave=0, **plane)
        variants["pyc. o0"] = LocalizeConfig(method="pycolmap", sift_first_octave=0, **plane)
    for method, cfg in variants.items():
        lmap = LocalizationMap(md, cam, cfg=cfg)
        pe, he, inl, tim = [], [], [], []
        for img, _R, c, th in photos:
            est = localize(img, lmap, cfg)
            if not est.ok:
                continue
            pe.append(np.linalg.norm(est.center - c) * 100)
            he.append(abs(math.degrees(math.remainder(est.heading - th, 2 * math.pi))))
            inl.append(est.num_inliers)
            tim.append([est.timings_s[k] * 1e3 for k in ("extract", "match", "pose", "total")])
        tim = np.array(tim).reshape(-1, 4)
        med_t = np.median(tim, axis=0) if len(tim) else [np.nan] * 4
        gross = int(np.sum(np.array(pe) > 25.0))
        print(
            f"{method:>9} {len(pe):>3}/{queries:<2} {gross:>5} {pct(pe, 50):7.2f}"
            f" {pct(pe, 90):7.2f}"
            f" {pct(pe, 50) / 2.54:7.2f} {pct(pe, 90) / 2.54:7.2f} {pct(he, 50):8.3f}"
            f" {pct(he, 90):8.3f} {pct(inl, 50):8.0f} {med_t[0]:8.1f} {med_t[1]:7.1f}"
            f" {med_t[2]:7.1f} {med_t[3]:8.1f}"
        )


def extraction_speed(world, repeats: int) -> None:
    rng = np.random.default_rng(5)
    R, c = camera_at(world, free_spot(world, rng, 0.5), 1.0)
    gray = load_gray(world.renderer.render(world.intrinsics, R, c, rng))
    print(f"\nSIFT extraction at {gray.shape[1]}x{gray.shape[0]} (median of {repeats})")
    print(f"{'extractor':>28} {'features':>8} {'ms':>8} {'ratio':>6}")
    loc = LocalizeConfig()
    sift = (loc.sift_max_features, loc.sift_num_threads)
    ref = None
    rows = [
        ("pycolmap first_octave=-1", lambda: extract_sift(gray, -1, *sift)),
        ("pycolmap first_octave=0", lambda: extract_sift(gray, 0, *sift)),
        ("opencv SIFT (not used)", lambda: cv2.SIFT_create().detectAndCompute(gray, None)),
    ]
    for name, fn in rows:
        ts = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            out = fn()
            ts.append(time.perf_counter() - t0)
        ms = float(np.median(ts)) * 1e3
        ref = ref or ms
        print(f"{name:>28} {len(out[0]):>8} {ms:8.1f} {ms / ref:6.2f}")


def whole_speed(world, md: MapDescriptors, cam, repeats: int) -> None:
    """Median time of the whole ``localize`` call on one photo (extract + match + pose)."""
    rng = np.random.default_rng(11)
    plane = {"camera_plane_z_m": world.scene.floor_z + world.cfg.camera.height_m}
    while True:  # a photo that localizes
        R, c = camera_at(world, free_spot(world, rng, 0.5), rng.uniform(0, 2 * math.pi))
        img = world.renderer.render(world.intrinsics, R, c, rng)
        if localize(img, LocalizationMap(md, cam), LocalizeConfig(**plane)).ok:  # default cfg
            break
    print(f"\nwhole localization of one 640x480 photo (median of {repeats})")
    print(f"{'config':>22} {'extract':>8} {'match':>7} {'pose':>7} {'total ms':>8} {'ratio':>6}")
    ref = None
    for name, cfg in {
        "pycolmap, octave -1": LocalizeConfig(method="pycolmap", sift_first_octave=-1, **plane),
        "dlt, octave -1": LocalizeConfig(method="dlt", sift_first_octave=-1, **plane),
        "pycolmap, octave 0": LocalizeConfig(method="pycolmap", sift_first_octave=0, **plane),
        "dlt, octave 0": LocalizeConfig(method="dlt", sift_first_octave=0, **plane),
    }.items():
        lmap = LocalizationMap(md, cam, cfg=cfg)
        t = []
        for _ in range(repeats):
            est = localize(img, lmap, cfg)
            t.append([est.timings_s[k] * 1e3 for k in ("extract", "match", "pose", "total")])
        m = np.median(np.array(t), axis=0)
        ref = ref or m[3]
        print(f"{name:>22} {m[0]:8.1f} {m[1]:7.1f} {m[2]:7.1f} {m[3]:8.1f} {m[3] / ref:6.2f}")


def matching_speed(md: MapDescriptors, n_map: int, n_query: int, repeats: int) -> None:
    rng = np.random.default_rng(7)
    base = md.descriptors
    reps = max(1, math.ceil(n_map / len(base)))
    rows = np.tile(np.arange(len(base)), reps)[:n_map]
    noise = rng.normal(0, 4.0, (n_map, 128)) * (np.arange(n_map) >= len(base))[:, None]
    big = np.clip(base[rows] + noise, 0, 255).astype(np.uint8)
    bigmap = MapDescriptors(md.point_ids[rows], md.xyz[rows], big)
    q_rows = rng.choice(len(base), n_query, replace=False)
    q = np.clip(base[q_rows] + rng.normal(0, 6.0, (n_query, 128)), 0, 255).astype(np.uint8)
    t0 = time.perf_counter()
    loc = LocalizeConfig()
    checks = loc.flann_checks
    index = DescriptorIndex(bigmap.descriptors, trees=4, checks=checks)
    build_s = time.perf_counter() - t0
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        m = match_to_map(q, index, bigmap, knn=loc.knn, ratio=loc.ratio)
        ts.append(time.perf_counter() - t0)
    flann_ms = float(np.median(ts)) * 1e3
    idx_f, _ = index.knn(q, 1)
    bf = cv2.BFMatcher(cv2.NORM_L2)
    t0 = time.perf_counter()
    exact = bf.knnMatch(q.astype(np.float32), bigmap.descriptors.astype(np.float32), k=1)
    bf_ms = (time.perf_counter() - t0) * 1e3
    exact_pid = bigmap.point_ids[[e[0].trainIdx for e in exact]]
    recall = float(np.mean(bigmap.point_ids[idx_f[:, 0]] == exact_pid))
    print(f"\nmatching {n_query} query descriptors against {n_map} map descriptors")
    print(f"{'method':>26} {'ms':>9} {'ratio':>7} {'NN point recall':>15}")
    name = f"FLANN 4 trees, {checks} checks"
    print(f"{name:>26} {flann_ms:9.1f} {flann_ms / bf_ms:7.3f} {recall:15.3f}")
    print(f"{'brute force (reference)':>26} {bf_ms:9.1f} {1.0:7.3f} {1.0:15.3f}")
    print(f"index build: {build_s:.2f} s; matches kept by the ratio test: {len(m)}")


def umeyama(src: np.ndarray, dst: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Similarity (s, R, t) minimising |dst - (s R src + t)|^2; src, dst (n, 3)."""
    mu_s, mu_d = src.mean(0), dst.mean(0)
    a, b = src - mu_s, dst - mu_d
    U, S, Vt = np.linalg.svd(b.T @ a / len(src))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    s = float(np.trace(np.diag(S) @ D) / (a**2).sum(axis=1).mean())
    return s, R, mu_d - s * R @ mu_s


def sfm_accuracy(sfm_dir: Path, capture_dir: Path, queries: int, seed: int = 3) -> None:
    from scenebot.capturelog import photo_records

    rec = pycolmap.Reconstruction(str(sfm_dir))
    truth = {
        Path(r["image"]).name: np.array(r["truth"]["center"])
        for r in photo_records(capture_dir / "log.jsonl")
        if "truth" in r
    }
    names = [im.name for im in rec.images.values() if Path(im.name).name in truth]
    cm = np.array([rec.find_image_with_name(n).projection_center() for n in names])
    cw = np.array([truth[Path(n).name] for n in names])
    s, Rw, tw = umeyama(cm, cw)
    resid = np.linalg.norm(cw - (s * cm @ Rw.T + tw), axis=1)
    print(
        f"\nsfm map {sfm_dir}: {len(names)} images aligned to truth (scale {s:.4f}, "
        f"median residual {np.median(resid) * 100:.2f} cm); {rec.num_points3D()} points"
    )
    scene = office(7)
    world = SimWorld(scene, SimConfig(), scene.start, seed=seed)
    rng = np.random.default_rng(seed)
    photos = []
    for _ in range(queries):
        xy, th = free_spot(world, rng, 0.3), rng.uniform(0, 2 * math.pi)
        R, c = camera_at(world, xy, th)
        photos.append((world.renderer.render(world.intrinsics, R, c, rng), c, th))
    print(
        f"{'method':>9} {'ok':>6} {'>25cm':>5} {'med cm':>7} {'p90 cm':>7} {'med in':>7}"
        f" {'p90 in':>7} {'med deg':>8} {'p90 deg':>8} {'inliers':>8} {'total ms':>8}"
    )
    OUT.mkdir(parents=True, exist_ok=True)
    for method, cfg in {
        "dlt": LocalizeConfig(method="dlt", sift_first_octave=-1),
        "pycolmap": LocalizeConfig(method="pycolmap", sift_first_octave=-1),
        "dlt o0": LocalizeConfig(method="dlt", sift_first_octave=0),
        "pyc. o0": LocalizeConfig(method="pycolmap", sift_first_octave=0),
    }.items():
        lmap = LocalizationMap.load(sfm_dir, cfg, cache_file=OUT / "sfm_map.flann")
        pe, he, inl, tot = [], [], [], []
        for img, c, th in photos:
            est = localize(img, lmap, cfg)
            if not est.ok:
                continue
            cw_est = s * Rw @ est.center + tw
            fwd = Rw @ est.R[2]
            pe.append(np.linalg.norm(cw_est - c) * 100)
            he.append(
                abs(math.degrees(math.remainder(math.atan2(fwd[1], fwd[0]) - th, 2 * math.pi)))
            )
            inl.append(est.num_inliers)
            tot.append(est.timings_s["total"] * 1e3)
        gross = int(np.sum(np.array(pe) > 25.0))
        print(
            f"{method:>9} {len(pe):>3}/{queries:<2} {gross:>5} {pct(pe, 50):7.2f}"
            f" {pct(pe, 90):7.2f} {pct(pe, 50) / 2.54:7.2f} {pct(pe, 90) / 2.54:7.2f}"
            f" {pct(he, 50):8.3f} {pct(he, 90):8.3f} {pct(inl, 50):8.0f} {pct(tot, 50):8.1f}"
        )


def follow_trial(scene, md: MapDescriptors, cam, n_goals: int, seed: int = 2) -> None:
    from scenebot.capture.follow import FollowConfig, PathFollower
    from scenebot.plan import PlanConfig, build_navgrid
    from scenebot.plan.path import GridPlanner
    from scenebot.robot.sim import SimCamera, SimRobot

    cfg = SimConfig()
    world = SimWorld(scene, cfg, scene.start, seed=seed)
    cam_z = scene.floor_z + cfg.camera.height_m
    # map frame convention: camera plane at z = 0
    lmap = LocalizationMap(
        MapDescriptors(md.point_ids, md.xyz - [0.0, 0.0, cam_z], md.descriptors), cam
    )
    rng = np.random.default_rng(seed)
    tri = scene.vertices[scene.triangles]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    k = rng.choice(len(tri), 60000, p=area / area.sum())
    u, v = rng.random((2, 60000))
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    pts = tri[k, 0] + u[:, None] * (tri[k, 1] - tri[k, 0]) + v[:, None] * (tri[k, 2] - tri[k, 0])
    pts[:, 2] -= cam_z
    lo, hi = scene.bounds
    pcfg = PlanConfig(
        obstacle_z_min_m=scene.floor_z + 0.03 - cam_z,
        obstacle_z_max_m=scene.floor_z + cfg.body.height_m - cam_z,
        margin_m=0.0,
        inflate_m=cfg.body.radius_m + 0.03,
        lethal_points=2.0,
    )
    planner = GridPlanner(
        build_navgrid(pts, np.array([lo[:2], hi[:2]]), pcfg), pcfg.simplify_factor
    )
    lcfg = LocalizeConfig()
    follower = PathFollower(
        SimRobot(world),
        SimCamera(world),
        lambda p: localize(p, lmap, lcfg),
        planner,
        FollowConfig(camera_forward_m=cfg.camera.forward_offset_m),
        OUT / "follow_photos",
        truth=world.truth_record,
    )
    here = np.array([scene.start.x, scene.start.y])
    print(f"\nfollowing {n_goals} chained goals in the office with visual localization")
    print(
        f"{'goal':>4} {'reached':>7} {'err cm':>7} {'obst':>4} {'fixes':>5} {'failed':>6}"
        f" {'motions':>7}  reason"
    )
    errs, ok = [], 0
    for i in range(n_goals):
        while True:
            g = free_spot(world, rng, 0.45)
            if np.hypot(*(g - here)) > 1.0 and hasattr(planner(here, g), "waypoints_xy"):
                break
        res = follower.go_to(g, goal_index=i)
        p = world.truth_pose
        err = math.hypot(p.x - g[0], p.y - g[1]) * 100
        errs.append(err)
        ok += res.reached and err < 10.0
        here = np.array([p.x, p.y])
        print(
            f"{i:>4} {res.reached!s:>7} {err:7.2f} {res.obstacles:>4} {res.localizations:>5}"
            f" {res.failed_localizations:>6} {res.motions:>7}  {res.reason}"
        )
    print(
        f"reached within 10 cm: {ok}/{n_goals}; median error {np.median(errs):.2f} cm; "
        f"max penetration into geometry {world.max_penetration_m * 100:.2f} cm"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spots", type=int, default=4)
    ap.add_argument("--headings", type=int, default=12)
    ap.add_argument("--queries", type=int, default=30)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--map-size", type=int, default=160_000)
    ap.add_argument("--follow", type=int, default=0, help="goals for the following trial")
    ap.add_argument("--skip-accuracy", action="store_true", help="no accuracy, no speed")
    ap.add_argument("--speed-only", action="store_true", help="extraction and matching speed")
    ap.add_argument("--sfm", type=Path, help="an sfm stage output folder (round_000/sfm)")
    ap.add_argument("--capture", type=Path, help="its capture folder (with log.jsonl)")
    args = ap.parse_args()
    scene = office(7)
    cfg = SimConfig()
    world = SimWorld(scene, cfg, scene.start, seed=0)
    t0 = time.perf_counter()
    md = build_office_map(world, args.spots, args.headings)
    print(
        f"office map: {len(md.point_ids)} descriptors of {len(np.unique(md.point_ids))} points"
        f" ({time.perf_counter() - t0:.1f} s to build/load)"
    )
    intr = world.intrinsics
    cam = pycolmap.Camera(
        model="PINHOLE",
        width=intr.width,
        height=intr.height,
        params=[intr.fx, intr.fy, intr.cx, intr.cy],
    )
    if not args.skip_accuracy and not args.speed_only:
        accuracy(world, md, cam, args.queries, check_pose=False)
        accuracy(world, md, cam, args.queries, check_pose=True)
    if not args.skip_accuracy or args.speed_only:
        extraction_speed(world, args.repeats)
        whole_speed(world, md, cam, args.repeats)
        matching_speed(md, args.map_size, 1000, args.repeats)
    if args.sfm is not None:
        if args.capture is None:
            ap.error("--sfm needs --capture (the capture folder whose log has the truth)")
        sfm_accuracy(args.sfm, args.capture, args.queries)
    if args.follow:
        follow_trial(scene, md, cam, args.follow)


if __name__ == "__main__":
    main()
