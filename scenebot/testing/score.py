"""Synthetic scenes with known geometry for tests and benchmarks of the score stages.

A box room (camera plane z = 0, floor below, ceiling above) with box furniture, as a triangle
mesh whose faces are subdivided into cells of about ``cell_m``, plus source cameras looking
horizontally, and points sampled on the visible surfaces.
"""

from __future__ import annotations

import numpy as np

from scenebot.geometry import Intrinsics, planar_cam_from_world


def grid_quad(origin: np.ndarray, u: np.ndarray, v: np.ndarray, nu: int, nv: int):
    """Triangulated parallelogram ``origin + a u + b v`` (a, b in [0, 1]).

    Args:
        origin: (3,) corner (m).
        u: (3,) first edge (m).
        v: (3,) second edge (m).
        nu: cells along u.
        nv: cells along v.

    Returns:
        verts (V, 3) float64 and faces (F, 3) int64.
    """
    a = np.linspace(0.0, 1.0, nu + 1)
    b = np.linspace(0.0, 1.0, nv + 1)
    A, Bm = np.meshgrid(a, b, indexing="ij")
    verts = origin + A.reshape(-1, 1) * u + Bm.reshape(-1, 1) * v
    idx = np.arange((nu + 1) * (nv + 1)).reshape(nu + 1, nv + 1)
    p00, p10 = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    p01, p11 = idx[:-1, 1:].ravel(), idx[1:, 1:].ravel()
    faces = np.concatenate([np.stack([p00, p10, p11], 1), np.stack([p00, p11, p01], 1)])
    return verts, faces


def box_mesh(lo, hi, cell_m: float = 0.25):
    """Closed axis-aligned box surface, each face subdivided into ~``cell_m`` cells.

    Args:
        lo: (3,) min corner (m).
        hi: (3,) max corner (m).
        cell_m: target cell size (m).

    Returns:
        verts (V, 3), faces (F, 3).
    """
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    ext = hi - lo
    parts = []
    for ax in range(3):
        a1, a2 = [k for k in range(3) if k != ax]
        u = np.zeros(3)
        u[a1] = ext[a1]
        v = np.zeros(3)
        v[a2] = ext[a2]
        nu = max(1, round(ext[a1] / cell_m))
        nv = max(1, round(ext[a2] / cell_m))
        for side in (lo, hi):
            o = lo.copy()
            o[ax] = side[ax]
            parts.append(grid_quad(o, u, v, nu, nv))
    return merge(parts)


def merge(parts):
    """Concatenate (verts, faces) meshes."""
    verts, faces, off = [], [], 0
    for v, f in parts:
        verts.append(v)
        faces.append(f + off)
        off += len(v)
    return np.concatenate(verts), np.concatenate(faces)


def room(
    size=(6.0, 4.0),
    floor_z: float = -0.3,
    ceil_z: float = 2.0,
    cell_m: float = 0.25,
    furniture: bool = True,
    wall_x: float | None = None,
    wall_gap=None,
):
    """A box room centred at the origin, optionally with furniture and an inner wall.

    Args:
        size: (sx, sy) room extent (m).
        floor_z: floor height (m, camera plane is 0).
        ceil_z: ceiling height (m).
        cell_m: mesh cell size (m).
        furniture: add a table-high box and a tall cabinet.
        wall_x: x (m) of a full-height inner wall across the room, or None.
        wall_gap: (y0, y1) door opening in that wall (m), or None for a closed wall.

    Returns:
        verts (V, 3) float64, faces (F, 3) int64.
    """
    sx, sy = size
    parts = [box_mesh((-sx / 2, -sy / 2, floor_z), (sx / 2, sy / 2, ceil_z), cell_m)]
    if furniture:
        parts.append(box_mesh((1.2, 0.6, floor_z), (2.2, 1.4, 0.45), cell_m))
        parts.append(box_mesh((-2.6, -1.9, floor_z), (-1.9, -1.3, 1.6), cell_m))
    if wall_x is not None:
        th = 0.1
        spans = (
            [(-sy / 2, sy / 2)]
            if wall_gap is None
            else [(-sy / 2, wall_gap[0]), (wall_gap[1], sy / 2)]
        )
        for y0, y1 in spans:
            parts.append(
                box_mesh((wall_x - th / 2, y0, floor_z), (wall_x + th / 2, y1, ceil_z), cell_m)
            )
    return merge(parts)


def ring_sources(centres_xy, n_per_ring: int = 12, phase: float = 0.0):
    """Source cameras turning in place at each centre (a photo every 360/n degrees).

    Args:
        centres_xy: (M, 2) positions (m).
        n_per_ring: photos per position.
        phase: heading of the first photo (rad).

    Returns:
        R (M*n, 3, 3), t (M*n, 3) cam_from_world, and poses (M*n, 3) as (x, y, theta).
    """
    c = np.asarray(centres_xy, float).reshape(-1, 2)
    th = phase + np.arange(n_per_ring) * 2 * np.pi / n_per_ring
    poses = np.array([(x, y, a) for x, y in c for a in th]).reshape(-1, 3)
    Rt = planar_cam_from_world(poses[:, 0], poses[:, 1], poses[:, 2])
    return Rt[:, :9].reshape(-1, 3, 3), Rt[:, 9:], poses


def default_intrinsics(width: int = 640, height: int = 480) -> Intrinsics:
    """The robot camera used in synthetic scenes (60 degree horizontal field of view)."""
    return Intrinsics.from_hfov(width, height, 60.0)


def sample_surface(verts, faces, n: int, rng: np.random.Generator):
    """Uniform random points on a triangle mesh with their face normals.

    Args:
        verts: (V, 3) vertices (m).
        faces: (F, 3) triangles.
        n: number of points.
        rng: random generator.

    Returns:
        points (n, 3), unit normals (n, 3).
    """
    tri = verts[faces]
    cr = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = 0.5 * np.linalg.norm(cr, axis=1)
    k = rng.choice(len(faces), size=n, p=area / area.sum())
    r1, r2 = rng.random(n), rng.random(n)
    s = np.sqrt(r1)
    w = np.stack([1 - s, s * (1 - r2), s * r2], 1)
    pts = np.einsum("nk,nkd->nd", w, tri[k])
    nrm = cr[k] / (np.linalg.norm(cr[k], axis=1, keepdims=True) + 1e-12)
    return pts, nrm


def visible_mask(verts, faces, R, t, intr: Intrinsics, pts, tol: float = 0.01) -> np.ndarray:
    """Which cameras see which points (in frame, in front, not occluded), by ray casting.

    Args:
        verts: (V, 3) scene mesh vertices (m).
        faces: (F, 3) triangles.
        R: (S, 3, 3) cam_from_world rotations.
        t: (S, 3) translations (m).
        intr: camera intrinsics.
        pts: (N, 3) points (m), on the mesh.
        tol: occlusion tolerance (m).

    Returns:
        (S, N) bool.
    """
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(np.asarray(verts, np.float32)),
        o3d.core.Tensor(np.asarray(faces, np.uint32)),
    )
    out = np.zeros((len(R), len(pts)), bool)
    for s in range(len(R)):
        q = pts @ R[s].T + t[s]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = intr.fx * q[:, 0] / q[:, 2] + intr.cx
            v = intr.fy * q[:, 1] / q[:, 2] + intr.cy
        inf = (q[:, 2] > 0.05) & (u >= 0) & (v >= 0) & (u < intr.width) & (v < intr.height)
        C = -R[s].T @ t[s]
        d = pts[inf] - C
        dist = np.linalg.norm(d, axis=1)
        rays = np.concatenate([np.broadcast_to(C, d.shape), d / dist[:, None]], 1)
        th = scene.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))["t_hit"].numpy()
        vis = np.zeros(len(pts), bool)
        vis[np.nonzero(inf)[0]] = th >= dist - tol
        out[s] = vis
    return out


def write_colmap_model(out_dir, intr: Intrinsics, R, t, pts, seen, rng=None) -> None:
    """Write a COLMAP binary model (cameras/images/points3D.bin) of known cameras and points.

    Args:
        out_dir: folder to create.
        intr: the one PINHOLE camera.
        R: (S, 3, 3) cam_from_world rotations.
        t: (S, 3) translations (m).
        pts: (N, 3) 3D points (m).
        seen: (S, N) bool observations (points seen by < 2 images are dropped).
        rng: optional generator for 0.3 px observation noise.
    """
    import tempfile
    from pathlib import Path

    import pycolmap
    from scipy.spatial.transform import Rotation

    keep = seen.sum(axis=0) >= 2
    pts, seen = pts[keep], seen[:, keep]
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "cameras.txt").write_text(
            f"1 PINHOLE {intr.width} {intr.height} {intr.fx} {intr.fy} {intr.cx} {intr.cy}\n"
        )
        tracks: list[list[str]] = [[] for _ in range(len(pts))]
        lines = []
        for s in range(len(R)):
            q = Rotation.from_matrix(R[s]).as_quat()  # x y z w
            ids = np.nonzero(seen[s])[0]
            pc = pts[ids] @ R[s].T + t[s]
            uv = np.stack(
                [intr.fx * pc[:, 0] / pc[:, 2] + intr.cx, intr.fy * pc[:, 1] / pc[:, 2] + intr.cy],
                1,
            )
            if rng is not None:
                uv += rng.normal(0, 0.3, uv.shape)
            lines.append(
                f"{s + 1} {q[3]} {q[0]} {q[1]} {q[2]} {t[s][0]} {t[s][1]} {t[s][2]} 1 im{s:04d}.jpg"
            )
            lines.append(
                " ".join(f"{a:.3f} {b:.3f} {p + 1}" for (a, b), p in zip(uv, ids, strict=True))
            )
            for k, p in enumerate(ids):
                tracks[p].append(f"{s + 1} {k}")
        (tmp / "images.txt").write_text("\n".join(lines) + "\n")
        (tmp / "points3D.txt").write_text(
            "\n".join(
                f"{p + 1} {x} {y} {z} 128 128 128 0.5 " + " ".join(tr)
                for p, ((x, y, z), tr) in enumerate(zip(pts, tracks, strict=True))
            )
            + "\n"
        )
        rec = pycolmap.Reconstruction(str(tmp))
        rec.write(str(out_dir))


def scorers(
    verts,
    faces,
    R,
    t,
    width: int = 40,
    height: int = 30,
    depth_width: int = 160,
    which: str = "both",
    **kw,
):
    """Taichi and/or reference scorers for a synthetic scene with :func:`default_intrinsics`.

    Args:
        verts: (V, 3) mesh vertices (m).
        faces: (F, 3) triangles.
        R: (S, 3, 3) source rotations (cam_from_world).
        t: (S, 3) source translations (m).
        width: candidate render width (pixels).
        height: candidate render height (pixels).
        depth_width: source depth-map width (pixels).
        which: ``"taichi"``, ``"reference"`` or ``"both"``.
        **kw: more keyword arguments for the taichi scorer (depth_tolerance, near_m,
            batch_size, backend, tile_px, per_view); the settings not given are
            :class:`~scenebot.score.config.ScoreConfig`'s.

    Returns:
        The scorer, or a (taichi, reference) tuple for ``"both"``.
    """
    from scenebot.score.config import ScoreConfig
    from scenebot.score.kernel import TaichiScorer, source_views_for_depth
    from scenebot.score.reference import ReferenceScorer

    K = default_intrinsics()
    sv, size = source_views_for_depth(R, t, [K] * len(R), depth_width)
    intr = K.scaled(width, height)
    cfg = ScoreConfig()
    kw = {
        "depth_tolerance": cfg.depth_tolerance,
        "near_m": cfg.near_m,
        "batch_size": cfg.batch_size,
        "backend": cfg.backend,
        **kw,
    }
    common = {k: v for k, v in kw.items() if k in ("depth_tolerance", "near_m")}
    out = []
    if which in ("taichi", "both"):
        out.append(TaichiScorer(verts, faces, sv, size, intr, **kw))
    if which in ("reference", "both"):
        out.append(ReferenceScorer(verts, faces, sv, size, intr, **common))
    return out[0] if len(out) == 1 else tuple(out)
