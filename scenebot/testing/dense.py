"""Synthetic multi-view scenes with known depth, for tests and benchmarks of the dense stage.

A closed room (floor, walls, ceiling) with boxes standing on the floor, covered by a view-
independent procedural texture (multi-octave 3D value noise times a per-surface tint, with
Lambertian shading from a fixed light), is ray cast with ``open3d.t.geometry.RaycastingScene``.
The views are built into a ``pycolmap.Reconstruction`` with the true cameras and a sparse set
of visible surface points, exactly what the SfM stage would hand over on a perfect run.

World frame as in the rest of scenebot: metres, z up, cameras in the plane z = 0 looking
horizontally; camera axes OpenCV/COLMAP (x right, y down, z forward).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import open3d as o3d
import pycolmap

from scenebot.dense.evaluate import sample_surface


@dataclass
class SyntheticView:
    """One rendered view.

    Attributes:
        name: image file name.
        R: (3, 3) cam_from_world rotation.
        t: (3,) cam_from_world translation, metres.
        image: (H, W, 3) uint8 RGB photo.
        depth: (H, W) float32 true z-depth, metres (0 where nothing is hit).
        normal: (H, W, 3) float32 true unit normal in the camera frame, facing the camera.
    """

    name: str
    R: np.ndarray
    t: np.ndarray
    image: np.ndarray
    depth: np.ndarray
    normal: np.ndarray


@dataclass
class SyntheticScene:
    """Triangle mesh of a scene plus rendering helpers.

    Attributes:
        vertices: (V, 3) float64 vertices, metres.
        triangles: (T, 3) int32 vertex indices.
        tints: (T, 3) float32 RGB tint per triangle in [0, 1].
    """

    vertices: np.ndarray
    triangles: np.ndarray
    tints: np.ndarray
    seed: int = 0
    _rc: o3d.t.geometry.RaycastingScene | None = field(default=None, repr=False)

    @property
    def raycaster(self) -> o3d.t.geometry.RaycastingScene:
        if self._rc is None:
            rc = o3d.t.geometry.RaycastingScene()
            rc.add_triangles(
                o3d.core.Tensor(self.vertices.astype(np.float32)),
                o3d.core.Tensor(self.triangles.astype(np.uint32)),
            )
            self._rc = rc
        return self._rc

    def legacy_mesh(self) -> o3d.geometry.TriangleMesh:
        """The scene as an open3d legacy mesh (for sampling and evaluation)."""
        mesh = o3d.geometry.TriangleMesh(
            o3d.utility.Vector3dVector(self.vertices),
            o3d.utility.Vector3iVector(self.triangles.astype(np.int32)),
        )
        mesh.compute_triangle_normals()
        return mesh


def _box(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    box = o3d.geometry.TriangleMesh.create_box(*(np.asarray(hi) - np.asarray(lo)))
    box.translate(np.asarray(lo, dtype=np.float64))
    return np.asarray(box.vertices), np.asarray(box.triangles)


def box_room_scene(
    room: tuple[float, float, float, float] = (-2.0, -1.5, 3.0, 1.5),
    floor_z: float = -0.3,
    ceiling_z: float = 1.6,
    boxes: list[tuple[tuple[float, float, float], tuple[float, float, float]]] | None = None,
    seed: int = 0,
) -> SyntheticScene:
    """A closed box-shaped room with boxes on its floor.

    Args:
        room: (xmin, ymin, xmax, ymax) of the room, metres.
        floor_z: floor height, metres (cameras are at z = 0).
        ceiling_z: ceiling height, metres.
        boxes: list of (lo, hi) corners, metres; default: three boxes in front of +x.
        seed: texture seed.

    Returns:
        The scene mesh with per-triangle tints.
    """
    if boxes is None:
        boxes = [
            ((1.4, -0.9, floor_z), (2.0, -0.2, floor_z + 0.7)),
            ((1.7, 0.3, floor_z), (2.3, 0.9, floor_z + 0.45)),
            ((2.5, -0.3, floor_z), (2.9, 0.3, floor_z + 1.2)),
        ]
    rng = np.random.default_rng(seed)
    verts, tris, tints = [], [], []
    offset = 0
    parts = [((room[0], room[1], floor_z), (room[2], room[3], ceiling_z)), *boxes]
    for lo, hi in parts:
        v, t = _box(np.array(lo), np.array(hi))
        verts.append(v)
        tris.append(t + offset)
        tints.append(np.repeat(rng.uniform(0.45, 1.0, (1, 3)), len(t), axis=0))
        offset += len(v)
    return SyntheticScene(
        vertices=np.concatenate(verts),
        triangles=np.concatenate(tris).astype(np.int32),
        tints=np.concatenate(tints).astype(np.float32),
        seed=seed,
    )


def _hash01(ix: np.ndarray, iy: np.ndarray, iz: np.ndarray, seed: int) -> np.ndarray:
    h = (
        ix.astype(np.uint64) * np.uint64(73856093)
        ^ iy.astype(np.uint64) * np.uint64(19349663)
        ^ iz.astype(np.uint64) * np.uint64(83492791)
        ^ np.uint64((seed * 2654435761) & 0xFFFFFFFF)
    ) & np.uint64(0xFFFFFFFF)
    h ^= h >> np.uint64(15)
    h = (h * np.uint64(0x2C1B3C6D)) & np.uint64(0xFFFFFFFF)
    h ^= h >> np.uint64(12)
    h = (h * np.uint64(0x297A2D39)) & np.uint64(0xFFFFFFFF)
    h ^= h >> np.uint64(15)
    return (h & np.uint64(0xFFFFFF)).astype(np.float64) / float(0xFFFFFF)


def value_noise(points: np.ndarray, freq: float, seed: int) -> np.ndarray:
    """Smooth 3D value noise.

    Args:
        points: (N, 3) positions, metres.
        freq: lattice frequency, cells per metre.
        seed: hash seed.

    Returns:
        (N,) values in [0, 1].
    """
    q = points * freq + 1000.0  # keep lattice indices positive
    i0 = np.floor(q).astype(np.int64)
    f = q - i0
    f = f * f * (3.0 - 2.0 * f)
    out = np.zeros(len(points))
    for dx in (0, 1):
        wx = f[:, 0] if dx else 1.0 - f[:, 0]
        for dy in (0, 1):
            wy = f[:, 1] if dy else 1.0 - f[:, 1]
            for dz in (0, 1):
                wz = f[:, 2] if dz else 1.0 - f[:, 2]
                out += wx * wy * wz * _hash01(i0[:, 0] + dx, i0[:, 1] + dy, i0[:, 2] + dz, seed)
    return out


def procedural_texture(points: np.ndarray, seed: int = 0) -> np.ndarray:
    """Rich view-independent grey texture: fractal value noise (4 to 64 cells per metre).

    Args:
        points: (N, 3) surface points, metres.
        seed: texture seed.

    Returns:
        (N,) albedo in [0.05, 0.95].
    """
    total = np.zeros(len(points))
    norm = 0.0
    for octave, freq in enumerate((4.0, 9.0, 19.0, 37.0, 71.0)):
        amp = 0.75**octave
        total += amp * value_noise(points, freq, seed + 17 * octave)
        norm += amp
    g = total / norm
    g = 0.5 + 0.5 * np.tanh(4.0 * (g - 0.5))  # spread the contrast
    return 0.05 + 0.9 * g


def look_at_pose(center: np.ndarray, heading_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """cam_from_world pose of a horizontal camera.

    Args:
        center: (3,) camera centre, metres.
        heading_rad: viewing direction in the xy plane, radians from +x towards +y.

    Returns:
        R (3, 3) and t (3,) with x_cam = R @ x_world + t.
    """
    fwd = np.array([np.cos(heading_rad), np.sin(heading_rad), 0.0])
    down = np.array([0.0, 0.0, -1.0])
    right = np.cross(down, fwd)
    R = np.stack([right, down, fwd])
    return R, -R @ np.asarray(center, dtype=np.float64)


def render_view(
    scene: SyntheticScene,
    K: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    width: int,
    height: int,
    supersample: int = 2,
    light_dir: tuple[float, float, float] = (0.3, -0.5, 0.8),
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ray cast one pinhole view.

    Args:
        scene: the scene.
        K: (3, 3) intrinsics of the output image, pixels.
        R: (3, 3) cam_from_world rotation.
        t: (3,) cam_from_world translation, metres.
        width: image width, pixels.
        height: image height, pixels.
        supersample: anti-aliasing factor of the photo (depth is sampled at pixel centres).
        light_dir: world direction towards the light.

    Returns:
        image (H, W, 3) uint8, depth (H, W) float32 z-depth in metres (0 = miss),
        normal (H, W, 3) float32 camera-frame unit normals facing the camera.
    """
    light = np.asarray(light_dir, dtype=np.float64)
    light /= np.linalg.norm(light)

    def cast(scale: int) -> tuple[np.ndarray, ...]:
        Ks = K.astype(np.float64).copy()
        Ks[:2] *= scale  # COLMAP convention: pixel (0, 0) covers [0, 1]^2, centre at 0.5
        h, w = height * scale, width * scale
        u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
        pix = np.stack([u, v, np.ones_like(u)], -1).reshape(-1, 3).astype(np.float64)
        dirs_cam = pix @ np.linalg.inv(Ks).T
        dirs_world = dirs_cam @ R  # R^T d
        origin = -R.T @ t
        rays = np.concatenate([np.broadcast_to(origin, dirs_world.shape), dirs_world], 1)
        ans = scene.raycaster.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))
        thit = ans["t_hit"].numpy().astype(np.float64)
        prim = ans["primitive_ids"].numpy().astype(np.int64)
        nrm = ans["primitive_normals"].numpy().astype(np.float64)
        hit = np.isfinite(thit)
        thit[~hit] = 0.0
        pts = origin + dirs_world * thit[:, None]
        return pts, thit, prim, nrm, hit, (h, w)

    pts, _thit, prim, nrm, hit, (h, w) = cast(supersample)
    rgb = np.zeros((len(pts), 3))
    if hit.any():
        alb = procedural_texture(pts[hit], scene.seed)
        shade = 0.55 + 0.45 * np.abs(nrm[hit] @ light)
        rgb[hit] = (alb * shade)[:, None] * scene.tints[prim[hit]]
    img = (np.clip(rgb, 0, 1) * 255.0).reshape(h, w, 3).astype(np.float32)
    if supersample > 1:
        img = cv2.resize(img, (width, height), interpolation=cv2.INTER_AREA)
    image = np.clip(np.round(img), 0, 255).astype(np.uint8)

    _, thit1, _, nrm1, hit1, _ = cast(1)
    depth = (thit1 * np.where(hit1, 1.0, 0.0)).reshape(height, width)  # z of dirs_cam == 1
    n_cam = nrm1 @ R.T
    u, v = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    ray = np.stack([u, v, np.ones_like(u)], -1).reshape(-1, 3) @ np.linalg.inv(K).T
    flip = np.sum(n_cam * ray, axis=1) > 0
    n_cam[flip] *= -1.0
    n_cam[~hit1] = 0.0
    return image, depth.astype(np.float32), n_cam.reshape(height, width, 3).astype(np.float32)


def make_dataset(
    out_dir: str | Path,
    scene: SyntheticScene,
    centers: np.ndarray,
    headings_rad: np.ndarray,
    width: int = 320,
    height: int = 240,
    focal_px: float | None = None,
    num_points: int = 4000,
    image_ext: str = ".jpg",
) -> tuple[pycolmap.Reconstruction, list[SyntheticView]]:
    """Render views, write the photos, and build a sparse model with the true cameras.

    Args:
        out_dir: folder that receives ``images/`` and ``sparse/`` (COLMAP binary model).
        scene: the scene to render.
        centers: (N, 3) camera centres, metres.
        headings_rad: (N,) viewing directions, radians.
        width: image width, pixels.
        height: image height, pixels.
        focal_px: focal length, pixels (default 0.83 * width, i.e. a 62 degree field of view).
        num_points: surface points sampled for the sparse model (only those seen by >= 2
            views are kept).
        image_ext: ``.jpg`` (quality 95, like the robot's photos) or ``.png``.

    Returns:
        The reconstruction (also written to ``out_dir/sparse``) and the rendered views.
    """
    out_dir = Path(out_dir)
    (out_dir / "images").mkdir(parents=True, exist_ok=True)
    (out_dir / "sparse").mkdir(parents=True, exist_ok=True)
    f = 0.83 * width if focal_px is None else focal_px
    K = np.array([[f, 0, width / 2.0], [0, f, height / 2.0], [0, 0, 1.0]])
    views: list[SyntheticView] = []
    for i, (c, hd) in enumerate(zip(centers, headings_rad, strict=True)):
        R, t = look_at_pose(np.asarray(c), float(hd))
        image, depth, normal = render_view(scene, K, R, t, width, height)
        name = f"view_{i:03d}{image_ext}"
        bgr = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
        params = [cv2.IMWRITE_JPEG_QUALITY, 95] if image_ext == ".jpg" else []
        cv2.imwrite(str(out_dir / "images" / name), bgr, params)
        views.append(SyntheticView(name, R, t, image, depth, normal))

    pts = sample_surface(scene.vertices, scene.triangles, num_points, seed=scene.seed)
    obs: dict[int, list[tuple[int, np.ndarray]]] = {}
    for vi, view in enumerate(views):
        pc = pts @ view.R.T + view.t
        z = pc[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = (pc @ K.T)[:, :2] / z[:, None]
        inside = (z > 0.05) & (uv[:, 0] >= 0.5) & (uv[:, 0] < width - 0.5)
        inside &= (uv[:, 1] >= 0.5) & (uv[:, 1] < height - 0.5)
        idx = np.flatnonzero(inside)
        # visibility: true depth at the pixel agrees with the point's depth
        d_img = view.depth[uv[idx, 1].astype(int), uv[idx, 0].astype(int)]
        vis = np.abs(d_img - z[idx]) < 0.02 * z[idx]
        for p in idx[vis]:
            obs.setdefault(int(p), []).append((vi, uv[p]))

    rec = pycolmap.Reconstruction()
    cam = pycolmap.Camera(
        model="PINHOLE", width=width, height=height, params=[f, f, K[0, 2], K[1, 2]], camera_id=1
    )
    rec.add_camera_with_trivial_rig(cam)
    kps: list[list[np.ndarray]] = [[] for _ in views]
    tracks: list[tuple[int, list[tuple[int, int]]]] = []
    for p, lst in obs.items():
        if len(lst) < 2:
            continue
        elems = []
        for vi, uv in lst:
            elems.append((vi + 1, len(kps[vi])))
            kps[vi].append(uv)
        tracks.append((p, elems))
    for vi, view in enumerate(views):
        kp = np.array(kps[vi], dtype=np.float64).reshape(-1, 2)
        img = pycolmap.Image(name=view.name, keypoints=kp, camera_id=1, image_id=vi + 1)
        pose = pycolmap.Rigid3d(pycolmap.Rotation3d(view.R), view.t)
        rec.add_image_with_trivial_frame(img, pose)
    for p, elems in tracks:
        track = pycolmap.Track()
        for image_id, p2d in elems:
            track.add_element(image_id, p2d)
        rec.add_point3D(pts[p], track, np.array([128, 128, 128], dtype=np.uint8))
    rec.write_binary(str(out_dir / "sparse"))
    return rec, views


def intrinsics(width: int, height: int, focal_px: float | None = None) -> np.ndarray:
    """(3, 3) intrinsics used by :func:`make_dataset` for the given size."""
    f = 0.83 * width if focal_px is None else focal_px
    return np.array([[f, 0, width / 2.0], [0, f, height / 2.0], [0, 0, 1.0]])


def stereo_rig(
    num_per_row: int = 7, half_width_m: float = 0.6, rows_x_m: tuple[float, ...] = (-0.5, 0.0)
) -> tuple[np.ndarray, np.ndarray]:
    """Camera centres and headings of a robot-like capture facing the boxes of
    :func:`box_room_scene`: rows of cameras across y, each turned slightly outwards.

    Args:
        num_per_row: cameras per row.
        half_width_m: the row spans y in [-half_width_m, half_width_m], metres.
        rows_x_m: x of each row, metres.

    Returns:
        centers (N, 3) metres (z = 0) and headings (N,) radians.
    """
    cs, hs = [], []
    for y in np.linspace(-half_width_m, half_width_m, num_per_row):
        for x in rows_x_m:
            cs.append([x, y, 0.0])
            hs.append(0.15 * y)
    return np.array(cs), np.array(hs)
