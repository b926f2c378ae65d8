"""The dense stage's depth maps, view by view, against the true scene (evaluation only).

Issue 7 asks, per view, that most pixels get a depth and that most of those depths are
right. :func:`evaluate_depth_maps` reads every depth map of a dense workspace, the measured
one (``stereo/depth_maps_measured``: PatchMatch after its filter) and the final one
(``stereo/depth_maps``: after plane completion, what fusion reads), and compares each with
the true depth along the same pixel rays: the true mesh ray-cast from the view's estimated
camera, brought into the world by the map's similarity. A pose error of the map therefore
counts against the depth map, as it would for anyone who uses it.

Per view: ``coverage``, the share of the pixels that see a surface and got a depth, and
``within``, the share of those depths within ``rel_tol`` (2%) of the truth
(:func:`scenebot.dense.evaluate.depth_map_metrics`). Summaries give the medians over the
views, the pixel-weighted shares, and how many views reach both bars (coverage >= 0.8 and
within >= 0.9); a breakdown by material says where pixels go without depth.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from scenebot.dense.evaluate import depth_map_metrics

log = logging.getLogger(__name__)

#: the issue's bars: a view reaches them when both hold
COVERAGE_BAR = 0.8
WITHIN_BAR = 0.9
#: the maps evaluated: key -> folder under the dense workspace's stereo/
KINDS = {"measured": "depth_maps_measured", "final": "depth_maps"}


def true_depth(
    K: np.ndarray, R: np.ndarray, centre: np.ndarray, width: int, height: int, sim, raycaster
) -> tuple[np.ndarray, np.ndarray]:
    """True z-depth (map units) and hit triangle of every pixel of a map-frame camera.

    Args:
        K: (3, 3) pinhole intrinsics (COLMAP: pixel centres at +0.5).
        R: (3, 3) cam_from_world rotation in the map frame.
        centre: (3,) camera centre in the map frame.
        width, height: image size (px).
        sim: the map -> world :class:`~scenebot.evaluate.metrics.Similarity`.
        raycaster: open3d ``RaycastingScene`` of the true mesh (world frame).

    Returns:
        (H, W) float32 depth in map units (0 where the ray hits nothing) and (H, W) int64
        triangle ids (-1 there).
    """
    import open3d as o3d

    jj, ii = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    ray = np.stack([jj, ii, np.ones_like(jj)], -1).reshape(-1, 3) @ np.linalg.inv(K).T
    # world direction scaled so that the hit parameter is the map-frame z-depth
    dirs = sim.scale * (ray @ np.asarray(R)) @ sim.R.T
    org = np.broadcast_to(sim.apply(np.asarray(centre)[None])[0], dirs.shape)
    ans = raycaster.cast_rays(o3d.core.Tensor(np.hstack([org, dirs]).astype(np.float32)))
    t = ans["t_hit"].numpy().reshape(height, width)
    hit = np.isfinite(t)
    prim = np.where(hit, ans["primitive_ids"].numpy().reshape(height, width), -1)
    return np.where(hit, t, 0.0).astype(np.float32), prim.astype(np.int64)


def _summary(rows: list[dict], kind: str, rel_tol: float) -> dict | None:
    vals = [r[kind] for r in rows if r.get(kind)]
    if not vals:
        return None
    cov = np.array([v["coverage"] for v in vals])
    wit = np.array([v["accuracy"] for v in vals])
    px = np.array([v["pixels"] for v in vals], np.float64)
    covered = cov * px
    return {
        "views": len(vals),
        "coverage_median": float(np.median(cov)),
        "coverage_pixels": float(covered.sum() / max(px.sum(), 1)),
        f"within_{100 * rel_tol:g}pct_median": float(np.median(wit)),
        f"within_{100 * rel_tol:g}pct_pixels": float(np.sum(wit * covered) / max(covered.sum(), 1)),
        "views_meeting_bars": int(np.sum((cov >= COVERAGE_BAR) & (wit >= WITHIN_BAR))),
        "bars": {"coverage": COVERAGE_BAR, "within": WITHIN_BAR, "rel_tol": rel_tol},
    }


def evaluate_depth_maps(dense_dir: Path, sim, scene, rel_tol: float, max_views: int) -> dict:
    """Every view's measured and final depth map against the truth.

    Args:
        dense_dir: the dense workspace (``final/dense``: ``sparse/`` and ``stereo/``).
        sim: the map -> world similarity of the map the workspace was built from.
        scene: the true :class:`~scenebot.scene.mesh.SceneMesh`.
        rel_tol: a depth is right within this share of the true depth
            (``evaluate.depth_rel_tol``).
        max_views: evaluate at most this many views, evenly spread (0: all;
            ``evaluate.depth_map_views``).

    Returns:
        ``views`` (per view: ``name``, and per kind ``coverage``, ``accuracy`` (the share
        within ``rel_tol``), ``median_rel_error``, ``pixels``), ``summary`` per kind
        (:func:`_summary`), and ``by_material`` per kind: each material's share of the
        pixels, the share of them with a depth and the share of those within ``rel_tol``.

    Raises:
        FileNotFoundError: the workspace has no undistorted model or no depth maps.
    """
    import pycolmap

    from scenebot.dense.colmap_io import read_array
    from scenebot.dense.evaluate import mesh_raycaster

    dense_dir = Path(dense_dir)
    if not (dense_dir / "sparse" / "images.bin").is_file():
        raise FileNotFoundError(f"no undistorted model in {dense_dir / 'sparse'}")
    rec = pycolmap.Reconstruction(str(dense_dir / "sparse"))
    rc = mesh_raycaster(scene.vertices, scene.triangles)
    mats = np.asarray(scene.material_ids)
    names = [m.name for m in scene.materials]

    def map_file(kind: str, name: str) -> Path | None:
        folder = dense_dir / "stereo" / KINDS[kind]
        for cand in (folder / f"{name}.geometric.bin", folder / f"{Path(name).name}.geometric.bin"):
            if cand.is_file():
                return cand
        return None

    ids = [i for i in sorted(rec.reg_image_ids()) if map_file("final", rec.image(i).name)]
    if not ids:
        raise FileNotFoundError(f"no depth maps in {dense_dir / 'stereo' / 'depth_maps'}")
    if 0 < max_views < len(ids):
        ids = [ids[k] for k in np.unique(np.linspace(0, len(ids) - 1, max_views).astype(int))]
    by_mat = {k: np.zeros((len(names), 3)) for k in KINDS}  # pixels, with depth, within
    rows = []
    for iid in ids:
        im = rec.image(iid)
        cam = rec.camera(im.camera_id)
        pose = im.cam_from_world()
        K, R = cam.calibration_matrix(), pose.rotation.matrix()
        truth, prim = true_depth(K, R, im.projection_center(), cam.width, cam.height, sim, rc)
        mat = np.where(prim >= 0, mats[np.clip(prim, 0, len(mats) - 1)], -1)
        row: dict = {"name": im.name}
        for kind in KINDS:
            f = map_file(kind, im.name)
            if f is None:
                continue
            d = read_array(f)
            if d.shape != truth.shape:
                raise ValueError(f"depth map {f} is {d.shape}, its camera {truth.shape}")
            m = depth_map_metrics(d, truth, rel_tol)
            row[kind] = {**m, "pixels": int((truth > 0).sum())}
            has = (d > 0) & (truth > 0)
            ok = np.zeros_like(has)
            ok[has] = np.abs(d[has] - truth[has]) < rel_tol * truth[has]
            seen = mat >= 0
            np.add.at(by_mat[kind], (mat[seen], 0), 1)
            np.add.at(by_mat[kind], (mat[has], 1), 1)
            np.add.at(by_mat[kind], (mat[ok], 2), 1)
        rows.append(row)
    out = {
        "views": rows,
        "summary": {k: _summary(rows, k, rel_tol) for k in KINDS},
        "by_material": {},
    }
    for kind, a in by_mat.items():
        total = a[:, 0].sum()
        if total == 0:
            continue
        order = np.argsort(-a[:, 0])
        out["by_material"][kind] = [
            {
                "material": names[j],
                "pixel_share": float(a[j, 0] / total),
                "with_depth": float(a[j, 1] / a[j, 0]),
                "within": float(a[j, 2] / a[j, 1]) if a[j, 1] else None,
            }
            for j in order
            if a[j, 0] > 0
        ]
    return out
