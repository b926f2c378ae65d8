"""The tour on a person's real photos: leave-one-out quality, black pixels, the object in view.

On a finished ``robot: photos`` map (sfm model, the photos, the dense workspace), with the
tour stage's own code and settings for a person's photos:

* leave-one-out PSNR/SSIM of ULR and of the nearest photo (the stage's protocol,
  :func:`scenebot.tour.evaluate.leave_one_out`: the proxy is the cloud fused from all photos);
* the same with the held-out photo also taken out of the proxy: every dense point whose
  fusion used the held-out photo's depth map is dropped (COLMAP's ``fused.ply.vis``). Stricter
  than re-fusing without it (points the other depth maps would have given alone are lost too),
  yet the other depth maps were still matched against the held-out photo;
* the tour itself (``--frames`` frames along the stage's path): black pixels per frame, and,
  with ``--given-cameras`` and ``--bbox``, the black pixels inside the object's projected
  bounding box. The box is mapped into the map's frame by a similarity fit of the registered
  camera centres to the given ones: ground truth for evaluation only, the tour never sees it.

Example (the Middlebury temple ring, see ``/work/shared/data/temple-sparse-ring/README.md``)::

    TI_SKIP_VERSION_CHECK=ON .venv/bin/python benchmarks/tour_photos.py \\
        --sparse results/temple/round_000/sfm --images PHOTOS --dense results/temple/final/dense \\
        --given-cameras PHOTOS/templeSR_par.txt \\
        --bbox -0.073568 0.021728 -0.012445 0.028855 0.181892 0.062736 --out /tmp/temple_tour
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")

import numpy as np


def loo_without_holdout_in_proxy(cfg, renderer, dense: Path) -> list[dict]:
    """Leave-one-out with every point fused from the held-out photo's depth map dropped."""
    import open3d as o3d
    import pycolmap

    from scenebot.testing.photos import read_fusion_visibility
    from scenebot.tour.evaluate import nearest_source, psnr
    from scenebot.tour.proxy import build_proxy
    from scenebot.tour.ulr import UlrRenderer

    vis = read_fusion_visibility(dense / "fused.ply.vis")
    ws = pycolmap.Reconstruction(str(dense / "sparse"))
    ws_names = [im.name for im in sorted(ws.images.values(), key=lambda im: im.image_id)]
    pcd = o3d.io.read_point_cloud(str(dense / "fused.ply"))
    pts, nrm, col = np.asarray(pcd.points), np.asarray(pcd.normals), np.asarray(pcd.colors)
    rows = []
    for j, s in enumerate(renderer.sources):
        if s.name not in ws_names:
            continue
        idx = ws_names.index(s.name)
        keep = np.array([idx not in v for v in vis])
        proxy = build_proxy(pts[keep], nrm[keep], col[keep], cfg.proxy, source="fused.ply")
        r = UlrRenderer(proxy, renderer.sources, cfg)
        res = r.render(s.camera, s.R, s.t, exclude={j})
        nn = nearest_source(r, j)
        rows.append({
            "name": s.name,
            "proxy_points_left": int(keep.sum()),
            "psnr_ulr": psnr(res.image, s.image),
            "psnr_nearest": psnr(r.sources[nn].image, s.image),
            "black_fraction": res.black_fraction,
        })  # fmt: skip
        r = rows[-1]
        print(f"  {s.name}: held out of the proxy too ({keep.mean():.0%} of the points left): "
              f"ULR {r['psnr_ulr']:.2f} dB, nearest {r['psnr_nearest']:.2f} dB")  # fmt: skip
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sparse", type=Path, required=True, help="sfm model folder")
    ap.add_argument("--images", type=Path, required=True, help="folder of the photos")
    ap.add_argument("--dense", type=Path, required=True,
                    help="dense workspace: fused.ply, fused.ply.vis, sparse/")  # fmt: skip
    ap.add_argument("--frames", type=int, default=120, help="tour frames to render")
    ap.add_argument("--given-cameras", type=Path, help="Middlebury *_par.txt (evaluation)")
    ap.add_argument("--bbox", type=float, nargs=6, help="object box lo xyz, hi xyz (given frame)")
    ap.add_argument("--set", default="{}", help='tour settings as JSON, e.g. \'{"ulr": {"k": 3}}\'')
    ap.add_argument("--out", type=Path, required=True, help="output folder (summary, pictures)")
    args = ap.parse_args()

    import cv2

    from scenebot.testing.photos import box_in_map, box_rect, read_middlebury_cameras
    from scenebot.tour.config import TourConfig
    from scenebot.tour.evaluate import leave_one_out
    from scenebot.tour.stage import (
        TourInputs,
        build_renderer,
        draw_path,
        plan_valid_path,
        tour_camera,
    )
    from scenebot.tour.ulr import FILL_NONE

    args.out.mkdir(parents=True, exist_ok=True)
    base = {"taichi_arch": "cpu", "path": {"frames": args.frames}}
    cfg = TourConfig.model_validate({**base, **json.loads(args.set)})
    t0 = time.perf_counter()
    inputs = TourInputs(args.sparse, args.images, args.dense / "fused.ply", photos=True)
    renderer, _ = build_renderer(cfg, inputs)
    cfg = renderer.cfg
    t_load = time.perf_counter() - t0
    t1 = time.perf_counter()
    path = plan_valid_path(cfg, renderer, None, photos=True)
    draw_path(
        args.out / "tour_path.png", path, renderer, "tour path (photos)", cfg.viewer.overview_cut_m
    )
    t_path = time.perf_counter() - t1
    corners = None
    if args.given_cameras and args.bbox:
        given = read_middlebury_cameras(args.given_cameras)
        names = [s.name for s in renderer.sources]
        corners, fit = box_in_map(names, renderer.centers, given, args.bbox[:3], args.bbox[3:])
        print(f"box mapped by a similarity fit of the camera centres (residual {fit:.1%})")
    cam = tour_camera(cfg, renderer.sources[0].camera)
    black, box_black, box_seen, t_frames = [], [], 0, []
    sheet = []
    for i in range(len(path)):
        t2 = time.perf_counter()
        res = renderer.render(cam, *path.pose(i))
        t_frames.append(time.perf_counter() - t2)
        black.append(res.black_fraction)
        if corners is not None:
            m = box_rect(cam, *path.pose(i), corners)
            if m is not None and m.any():
                box_seen += 1
                box_black.append(int((m & (res.fill == FILL_NONE)).sum()))
        if i % max(1, len(path) // 6) == 0 and len(sheet) < 6:
            sheet.append(res.image[::2, ::2])
    cv2.imwrite(str(args.out / "tour_frames.jpg"),
                cv2.cvtColor(np.concatenate(sheet, 1), cv2.COLOR_RGB2BGR))  # fmt: skip
    ev = leave_one_out(renderer, renderer.num_sources, progress=False)
    box_loo = []
    if corners is not None:
        for s in renderer.sources:
            m = box_rect(s.camera, s.R, s.t, corners)
            j = renderer.sources.index(s)
            res = renderer.render(s.camera, s.R, s.t, exclude={j})
            box_loo.append(int((m & (res.fill == FILL_NONE)).sum()) if m is not None else -1)
    strict = loo_without_holdout_in_proxy(cfg, renderer, args.dense)
    sm = ev["summary"]
    out = {
        "photos": renderer.num_sources,
        "frames": len(path),
        "path_kind": path.kind,
        "path_closed": path.closed,
        "path_dropped_frames": path.dropped,
        "tour_black_fraction_mean": float(np.mean(black)),
        "tour_black_fraction_max": float(np.max(black)),
        "frames_with_box_in_view": box_seen,
        "black_pixels_in_box_tour": int(np.sum(box_black)) if corners is not None else None,
        "black_pixels_in_box_loo": int(np.sum([b for b in box_loo if b > 0])) if box_loo else None,
        "loo": {k: sm[k] for k in sm},
        "loo_gain_db_mean": sm["mean_psnr_ulr"] - sm["mean_psnr_nearest"],
        "loo_gain_db_median": float(
            np.median([r["psnr_ulr"] - r["psnr_nearest"] for r in ev["per_view"]])
        ),
        "loo_per_view": ev["per_view"],
        "loo_holdout_out_of_proxy": {
            "mean_psnr_ulr": float(np.mean([r["psnr_ulr"] for r in strict])),
            "mean_psnr_nearest": float(np.mean([r["psnr_nearest"] for r in strict])),
            "median_gain_db": float(np.median([r["psnr_ulr"] - r["psnr_nearest"] for r in strict])),
            "per_view": strict,
        },
        "load_s": t_load,
        "path_s": t_path,
        "frame_s_median": float(np.median(t_frames)),
    }
    (args.out / "tour_photos.json").write_text(json.dumps(out, indent=1))
    short = {k: v for k, v in out.items() if k not in ("loo_per_view", "loo")}
    short["loo_holdout_out_of_proxy"] = {
        k: v for k, v in out["loo_holdout_out_of_proxy"].items() if k != "per_view"
    }
    short["loo_mean_psnr_ulr"] = sm["mean_psnr_ulr"]
    short["loo_mean_psnr_nearest"] = sm["mean_psnr_nearest"]
    print(json.dumps(short, indent=1))


if __name__ == "__main__":
    main()
