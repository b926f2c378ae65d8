"""A small synthetic capture for tests of the tour: photos, a sparse model and a dense cloud.

The box room of :mod:`scenebot.dense.synthetic` (view-independent procedural texture) is
photographed by a robot-like rig: a few stops, each a circle of photos turned in place, like
round 0 of the real capture. The "dense cloud" is sampled from the true surfaces (positions,
normals and colours), so the renderer is tested against known geometry.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scenebot.dense import synthetic as syn


@dataclass
class TourDataset:
    """Files of a synthetic capture.

    Attributes:
        root: folder; the model's image names are relative to ``root``.
        sparse_dir: COLMAP binary model.
        dense_ply: the sampled cloud (PLY with normals and colours).
        scene: the scene (for true renders).
        K: (3, 3) intrinsics of the photos.
        width: photo width, pixels.
        height: photo height, pixels.
    """

    root: Path
    sparse_dir: Path
    dense_ply: Path
    scene: syn.SyntheticScene
    K: np.ndarray
    width: int
    height: int


def rig(
    stops: tuple[tuple[float, float], ...] = ((-0.8, -0.4), (-0.6, 0.5), (0.4, 0.0)),
    per_stop: int = 12,
    offset_m: float = 0.05,
) -> tuple[np.ndarray, np.ndarray]:
    """Camera centres (N, 3) and headings (N,) of circles of photos at each stop.

    The camera sits ``offset_m`` in front of the turning axis, like the robot's.
    """
    cs, hs = [], []
    for x, y in stops:
        for h in np.linspace(0, 2 * np.pi, per_stop, endpoint=False):
            cs.append([x + offset_m * np.cos(h), y + offset_m * np.sin(h), 0.0])
            hs.append(h)
    return np.array(cs), np.array(hs)


def make_tour_dataset(
    out_dir: str | Path,
    width: int = 128,
    height: int = 96,
    per_stop: int = 12,
    num_points: int = 200000,
    seed: int = 0,
) -> TourDataset:
    """Render the photos and write the model and the cloud under ``out_dir``.

    Returns:
        The dataset (``root/images/view_XXX.jpg`` named ``images/view_XXX.jpg`` in the model).
    """
    import open3d as o3d
    import pycolmap

    out = Path(out_dir)
    scene = syn.box_room_scene(seed=seed)
    centers, heads = rig(per_stop=per_stop)
    rec, _views = syn.make_dataset(out, scene, centers, heads, width, height, num_points=3000)
    # names relative to the root, like the robot's round_000/capture/images/...
    for img in rec.images.values():
        img.name = f"images/{img.name}"
    sparse = out / "sfm"
    sparse.mkdir(parents=True, exist_ok=True)
    rec.write_binary(str(sparse))
    pts = syn.sample_surface(scene.vertices, scene.triangles, num_points, seed=seed)
    col = syn.procedural_texture(pts, scene.seed)
    # normal and tint of the surface each point lies on
    rc = scene.raycaster
    ans = rc.compute_closest_points(o3d.core.Tensor(pts.astype(np.float32)))
    prim = ans["primitive_ids"].numpy().astype(np.int64)
    nrm = ans["primitive_normals"].numpy().astype(np.float64)
    tint = scene.tints[prim]
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    pcd.normals = o3d.utility.Vector3dVector(nrm)
    pcd.colors = o3d.utility.Vector3dVector(np.clip(col[:, None] * tint, 0, 1))
    ply = out / "fused.ply"
    o3d.io.write_point_cloud(str(ply), pcd)
    K = syn.intrinsics(width, height)
    _ = pycolmap  # the model is written by make_dataset
    return TourDataset(out, sparse, ply, scene, K, width, height)
