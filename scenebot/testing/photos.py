"""Ground truth of real photo sets with calibrated cameras, for evaluation only.

The Middlebury multi-view sets (e.g. ``templeSparseRing``, see
``/work/shared/data/temple-sparse-ring/README.md``) give each photo's ``K [R | t]`` in their
own metric frame and the object's bounding box. A map made from the photos alone lives in
another frame (its own scale); the registered camera centres, fitted to the given ones by a
similarity, carry the box into it. Nothing here may steer a stage: tests and benchmarks only.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scenebot.sfm.evaluate import umeyama


def read_middlebury_cameras(par: str | Path) -> dict[str, np.ndarray]:
    """Camera centres of a Middlebury ``*_par.txt`` (first line the count, then
    ``name k11..k33 r11..r33 t1 t2 t3`` per photo, world to camera): photo name -> (3,)
    centre ``-R^T t`` (metres, the set's frame); read by the evaluation's reader."""
    from scenebot.evaluate.reference import read_reference_cameras

    return {name: centre for name, (_, centre) in read_reference_cameras(par).items()}


def box_in_map(
    names: list[str], centers: np.ndarray, given: dict[str, np.ndarray], lo, hi
) -> tuple[np.ndarray, float]:
    """The corners of a box given in the set's frame, in the map's frame.

    Args:
        names: the map's photo names (only their file names are matched).
        centers: (N, 3) the map's camera centres of those photos.
        given: :func:`read_middlebury_cameras`.
        lo: (3,) lower corner of the box (the set's frame).
        hi: (3,) upper corner.

    Returns:
        (8, 3) corners in the map's frame, and the fit's median centre residual relative to
        the cameras' spread (fraction).
    """
    pick = [i for i, n in enumerate(names) if Path(n).name in given]
    src = np.array([given[Path(names[i]).name] for i in pick])
    dst = np.asarray(centers, np.float64)[pick]
    s, R, t = umeyama(src, dst)
    res = np.linalg.norm(s * src @ R.T + t - dst, axis=1)
    spread = float(np.linalg.norm(dst - dst.mean(0), axis=1).mean())
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])], np.float64)  # fmt: skip
    return s * corners @ R.T + t, float(np.median(res) / max(spread, 1e-12))


def box_rect(cam, R: np.ndarray, t: np.ndarray, corners: np.ndarray) -> np.ndarray | None:
    """The bounding rectangle of a box's projection into a view, as a pixel mask.

    Args:
        cam: :class:`scenebot.tour.camera.Camera` of the view.
        R: (3, 3) cam_from_world rotation.
        t: (3,) cam_from_world translation.
        corners: (8, 3) the box's corners.

    Returns:
        (H, W) bool (all False when the box is outside the view), or None when a corner is
        behind the camera.
    """
    xc = np.asarray(corners) @ np.asarray(R).T + np.asarray(t)
    if (xc[:, 2] <= 0).any():
        return None
    uv = cam.project(xc)
    u0, v0 = np.floor(uv.min(0)).astype(int)
    u1, v1 = np.ceil(uv.max(0)).astype(int)
    m = np.zeros((cam.height, cam.width), bool)
    m[max(v0, 0) : max(min(v1, cam.height), 0), max(u0, 0) : max(min(u1, cam.width), 0)] = True
    return m


def read_fusion_visibility(path: str | Path) -> list[np.ndarray]:
    """COLMAP's ``fused.ply.vis``: per fused point, the indices of the images (the dense
    workspace's, in image-id order) whose depth maps it was fused from."""
    raw = Path(path).read_bytes()
    n = int(np.frombuffer(raw[:8], np.uint64)[0])
    a = np.frombuffer(raw[8:], np.uint32)
    out, i = [], 0
    for _ in range(n):
        k = int(a[i])
        out.append(a[i + 1 : i + 1 + k])
        i += 1 + k
    return out
