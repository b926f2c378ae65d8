"""Where the dense model's completeness is lost: not photographed, or photographed and not
reconstructed (evaluation only: true poses and the true scene).

The observable surface (:mod:`scenebot.evaluate.observable`) is what a robot *could* see.
Two different things keep a part of it out of the dense cloud: no photo (or one) of the
campaign saw it, which is the capture's loss, or enough photos saw it and multi-view stereo
found no depth there, which is the dense stage's (plain paint, a ceiling seen at a grazing
angle). :func:`photo_view_counts` counts, per surface sample, the campaign's photos that see
it (true pose, in the frame, not occluded: a depth test against the true scene rendered at
low resolution); :func:`completeness_breakdown` splits the completeness by that count and by
the surface's material, with each material's texture contrast (the standard deviation of its
texture's grey levels: what photometric stereo has to work with).

:func:`coverage_by_photo_count` follows the same visibility photo by photo, in capture order:
the share of the observable surface that the first n photos see once and twice, n = 5, 10,
..., N (the capture's coverage curve; the baselines compare campaigns by it).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence

import numpy as np

#: resolution of the depth maps of the visibility test (px); a sample is seen when its depth
#: agrees with the rendered one within max(DEPTH_TOL_M, DEPTH_REL_TOL * depth)
VIEW_SIZE = (160, 120)
DEPTH_TOL_M = 0.03
DEPTH_REL_TOL = 0.02
#: the view-count classes of the breakdown
VIEW_CLASSES = ((0, 0, "0"), (1, 1, "1"), (2, None, ">=2"))
#: photo counts of the coverage curve: every COVERAGE_STEP photos (and the last)
COVERAGE_STEP = 5


def photo_visibility(
    points: np.ndarray,
    poses: Sequence[tuple[np.ndarray, np.ndarray]],
    scene,
    hfov_deg: float,
    size: tuple[int, int] = VIEW_SIZE,
) -> Iterator[np.ndarray]:
    """Per photo, in the order of ``poses``, the surface samples it sees.

    A sample is seen when it lies in front of the camera, projects into the frame and its
    depth agrees with the true scene's depth map there (within max(DEPTH_TOL_M,
    DEPTH_REL_TOL * depth)): one render at ``size`` per photo.

    Args:
        points: (M, 3) surface samples (world, m).
        poses: (R_cam_from_world, centre) per photo
            (:func:`scenebot.evaluate.metrics.true_photo_poses`).
        scene: the true :class:`~scenebot.scene.mesh.SceneMesh`.
        hfov_deg: the photos' horizontal field of view (deg).
        size: (width, height) of the depth maps of the visibility test.

    Yields:
        Per photo, the (K,) increasing int32 indices into ``points`` of the samples it sees.
    """
    from scenebot.geometry import Intrinsics
    from scenebot.sim.renderer import Renderer

    points = np.asarray(points, np.float64)
    w, h = size
    intr = Intrinsics.from_hfov(w, h, hfov_deg)
    renderer = Renderer(scene, noise_sigma=0.0, antialias=False)
    for R, c in poses:
        _, depth = renderer.render(intr, R, c, return_depth=True)
        X = (points - c) @ R.T
        front = np.flatnonzero(X[:, 2] > 0.05)
        z = X[front, 2]
        u = intr.fx * X[front, 0] / z + intr.cx
        v = intr.fy * X[front, 1] / z + intr.cy
        ui, vi = np.round(u).astype(np.int64), np.round(v).astype(np.int64)
        inside = (ui >= 0) & (ui < w) & (vi >= 0) & (vi < h)
        d = depth[vi[inside], ui[inside]]
        zi = z[inside]
        seen = np.abs(d - zi) < np.maximum(DEPTH_TOL_M, DEPTH_REL_TOL * zi)
        yield front[inside][seen].astype(np.int32)


def count_views(visibility: Iterable[np.ndarray], n_samples: int) -> np.ndarray:
    """(n_samples,) int32: how many of the photos of ``visibility`` see each sample
    (:func:`photo_visibility`'s output)."""
    counts = np.zeros(n_samples, np.int32)
    for idx in visibility:
        counts[idx] += 1  # a photo's indices are distinct
    return counts


def photo_view_counts(
    points: np.ndarray,
    poses: Sequence[tuple[np.ndarray, np.ndarray]],
    scene,
    hfov_deg: float,
    size: tuple[int, int] = VIEW_SIZE,
) -> np.ndarray:
    """Per surface sample, the number of photos that see it: (M,) int32 counts (the
    arguments are :func:`photo_visibility`'s)."""
    vis = photo_visibility(points, poses, scene, hfov_deg, size)
    return count_views(vis, len(points))


def coverage_by_photo_count(
    visibility: Iterable[np.ndarray],
    weights: np.ndarray,
    step: int = COVERAGE_STEP,
) -> dict[str, list]:
    """The capture's coverage curve: the share of the surface seen by >= 1 and by >= 2 of
    the first n photos, for n = step, 2 step, ..., N (and N itself).

    Args:
        visibility: per photo, in capture order (round 0's photos, then round 1's, ...), the
            indices of the samples it sees (:func:`photo_visibility`); read once.
        weights: (M,) the samples' areas (m^2): the shares are of the area, as
            :func:`completeness_breakdown`'s ``photographed_share`` (which the last
            ``seen_2`` equals); ones give shares of the samples.
        step: photos between two points of the curve.

    Returns:
        ``photos`` (the n), ``seen_1`` and ``seen_2`` (shares in [0, 1], one per n); all
        empty without photos.
    """
    if step < 1:
        raise ValueError(f"coverage step must be >= 1 photo, got {step}")
    w = np.asarray(weights, np.float64)
    total = float(w.sum())
    counts = np.zeros(len(w), np.int32)
    out: dict[str, list] = {"photos": [], "seen_1": [], "seen_2": []}

    def record(n: int) -> None:
        out["photos"].append(n)
        for k in (1, 2):
            out[f"seen_{k}"].append(float(w[counts >= k].sum()) / total if total > 0 else 0.0)

    n = 0
    for n, idx in enumerate(visibility, start=1):
        counts[idx] += 1
        if n % step == 0:
            record(n)
    if n and (not out["photos"] or out["photos"][-1] != n):
        record(n)
    return out


def texture_contrast(texture: np.ndarray) -> float:
    """Standard deviation of a texture's grey levels (0-255)."""
    t = np.asarray(texture, np.float64)
    grey = t[..., :3] @ np.array([0.299, 0.587, 0.114]) if t.ndim == 3 else t
    return float(grey.std())


def completeness_breakdown(
    distances: np.ndarray,
    weights: np.ndarray,
    views: np.ndarray,
    material_ids: np.ndarray,
    materials: Sequence,
    thresholds_m: Sequence[float] = (0.01, 0.02, 0.05),
) -> dict:
    """Completeness of the observable surface split by photo count and by material.

    Args:
        distances: (M,) distance of each observable sample to the nearest cloud point (m).
        weights: (M,) the samples' areas (m^2).
        views: (M,) photos that see each sample (:func:`photo_view_counts`).
        material_ids: (M,) material index of each sample's triangle.
        materials: the scene's materials (``name``, ``texture``).
        thresholds_m: distances (m).

    Returns:
        ``photographed_share`` (area seen by >= 2 photos), ``by_views`` (per class: area
        share and completeness per threshold) and ``by_material`` (per material, largest
        area first: area share, photographed share, texture contrast, completeness).
    """
    d = np.asarray(distances, np.float64)
    w = np.asarray(weights, np.float64)
    views = np.asarray(views)
    total = float(w.sum())

    def comp(mask: np.ndarray) -> dict[str, float | None]:
        a = float(w[mask].sum())
        return {
            f"{round(t * 100, 1):g}cm": (float(w[mask & (d < t)].sum()) / a if a > 0 else None)
            for t in thresholds_m
        }

    by_views = []
    for lo, hi, label in VIEW_CLASSES:
        m = (views >= lo) & (views <= hi if hi is not None else True)
        by_views.append({"views": label, "area_share": float(w[m].sum()) / total,
                         "completeness": comp(m)})  # fmt: skip
    by_material = []
    mids = np.asarray(material_ids)
    for mi in np.unique(mids):
        m = mids == mi
        area = float(w[m].sum())
        by_material.append(
            {
                "material": materials[mi].name,
                "area_share": area / total,
                "photographed_share": float(w[m & (views >= 2)].sum()) / area if area else 0.0,
                "texture_contrast": texture_contrast(materials[mi].texture),
                "completeness": comp(m),
            }
        )
    by_material.sort(key=lambda r: -r["area_share"])
    photographed = views >= 2
    return {
        "photographed_share": float(w[photographed].sum()) / total,
        "completeness_where_photographed": comp(photographed),
        "by_views": by_views,
        "by_material": by_material,
        "view_test": {
            "size": list(VIEW_SIZE),
            "depth_tol_m": DEPTH_TOL_M,
            "depth_rel_tol": DEPTH_REL_TOL,
        },
    }
