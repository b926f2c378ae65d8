"""The rendering-quality score in taichi (paper section IV.B), batched over candidates.

Definition (shared with :mod:`scenebot.score.reference`): for a candidate camera at L, every
pixel p of a low-resolution render of the mesh gives the first surface point P on its ray.
For every source camera C_i (at L_i) that sees P -- P is in front of C_i, projects inside its
image, and its depth is at most ``(1 + depth_tolerance)`` times the largest depth of the 2x2
pixels of C_i's depth map around the projection -- the angle
``theta_i = angle(L - P, L_i - P)`` is formed. The pixel score is ``min_i theta_i`` (degrees),
or 180 degrees when no source sees P. Pixels whose ray hits nothing are left out: they carry no
information about the map (the mesh has a hole there), and the caller gets the fraction of
pixels that hit (``hit_fraction``) to judge such views. The view score is the mean pixel
score over the hit pixels (degrees); a view that hits nothing scores NaN.

Both passes run in taichi, batched over ``batch_size`` candidates per launch:

1. Primary visibility: a rasterizer writes the z-buffer of every view (edge functions with
   perspective-correct depth for triangles beyond the near plane, exact ray-triangle tests
   for triangles that cross it; triangles whose bounding sphere misses the frustum are skipped).
   The same kernel makes the source depth maps once per map (at ``source_depth_width``) and
   the candidate renders once per batch. On a CPU each thread owns whole views (plain writes);
   on a GPU threads own (view, chunk of triangles) pairs and write with atomic min.
2. Angles: the image is cut into tiles (``tile_px``). For every tile the sources whose view
   frustum can hold one of the tile's hit points are kept (plane tests against the tile's
   bounding box: exact culling), sorted by a lower bound of their angle over the whole tile.
   Every pixel then walks its tile's list, stops when the next lower bound is not below its
   best angle so far (exact early exit), and runs the depth-map visibility test only for a
   source that would lower its current minimum. So the result equals the brute-force
   definition; only the work differs.

On a CPU (``per_view``, the default there) all passes of a view run in one launch and on one
thread, while the view's z-buffer and tile lists are in that thread's cache, with less work
than the GPU's batched passes (same results up to float rounding):

- taichi splits a CPU loop into blocks of at least 512 iterations that the threads take in
  turn, so the loop runs over 512 tasks per ``VIEWS_PER_BLOCK`` views (a loop over 256 views
  would use one thread; a thread that other work on its core holds up takes fewer blocks);
- triangles are stored in Z-order and culled by clusters of 32 before their own test; the
  z-buffer keeps the largest 1/z (no division and no branch per covered pixel: branch
  mispredictions at triangle edges cost more than the arithmetic);
- sources are culled against the whole view's box, then blocks of 2x2 tiles, then tiles; the
  camera's share of each lower bound also uses the tile's corner-pixel rays; keys come from
  the angle-sum rules instead of inverse trigonometry;
- the depth test reads a precomputed 2x2 maximum (one load) and, first, the least and largest
  of those over 4x4 blocks (16 times smaller, mostly in cache), which decide most tests;
- a source's angle depends on its centre only: the cameras at one centre (a photo ring's) are
  one entry of a tile's list (one key; its cameras are tried in turn until one sees the
  point), and no camera at the centre of the best source so far is tested;
- the search keeps cosines (and the pixel's ray unnormalised); a pass of its own turns them
  into degrees with an inline arc cosine.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from scenebot.geometry import Intrinsics
from scenebot.score.geometry import VIEW_COLS, candidate_views, pack_views

log = logging.getLogger(__name__)

FAR = 1.0e30
"""Depth of a pixel whose ray hits nothing (m)."""

_TI_STATE: dict[str, object] = {}

TILE_PX_BATCHED = (8, 12)
"""Default tile size (pixels) of the batched (GPU) passes."""
TILE_PX_PER_VIEW = (10, 10)
"""Default tile size (pixels) of the per-view (CPU) pass."""
VIEWS_PER_BLOCK = 8
"""Views per block of parallel tasks of the per-view (CPU) kernels: the threads take the
blocks in turn, so a thread whose core other work holds up takes fewer of them."""


def init_taichi(backend: str) -> str:
    """Start taichi once per process, without crashing on machines that lack a GPU.

    ``ti.init(arch=ti.gpu)`` segfaults on some machines without a GPU, so the GPU backends are
    asked for explicitly (CUDA, then Vulkan) and taichi falls back to the CPU when neither is
    there.

    Args:
        backend: ``"auto"`` (GPU when present, else CPU), ``"cpu"``, or ``"gpu"`` (raise when no
            GPU backend starts).

    Re-initialising (asking for another backend than the current one) invalidates every
    existing :class:`TaichiScorer`; with ``"auto"``, a taichi runtime that another module of the
    process already started is reused as it is.

    Returns:
        The name of the arch taichi runs on (e.g. ``"x64"``, ``"cuda"``).

    Raises:
        RuntimeError: ``backend="gpu"`` but no GPU backend is available (set
            ``score.backend`` to ``auto`` or ``cpu``).
    """
    import os

    os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")
    import taichi as ti

    if backend not in ("auto", "cpu", "gpu"):
        raise ValueError(f"score.backend must be auto, cpu or gpu, not {backend!r}")
    prog = ti.lang.impl.get_runtime().prog
    if prog is None or prog is not _TI_STATE.get("prog"):
        _TI_STATE.clear()  # never started, or another module re-initialised taichi since
    current = _TI_STATE.get("backend")
    if current == backend or (current is not None and backend == "auto"):
        return str(_TI_STATE["arch"])
    if current is None and backend == "auto" and prog is not None:
        # another part of this process started taichi: reuse it rather than reset its data
        arch = ti.lang.impl.current_cfg().arch.name
        _TI_STATE.update(backend=backend, arch=arch, prog=prog)
        return arch
    if backend == "cpu":
        ti.init(arch=ti.cpu, offline_cache=True, log_level=ti.WARN)
    else:
        ti.init(arch=[ti.cuda, ti.vulkan], offline_cache=True, log_level=ti.WARN)
    arch = ti.lang.impl.current_cfg().arch.name
    _TI_STATE.pop("kernels", None)
    _TI_STATE["prog"] = ti.lang.impl.get_runtime().prog
    if backend == "gpu" and arch not in ("cuda", "vulkan"):
        _TI_STATE.update(backend="auto", arch=arch)
        raise RuntimeError(
            "score.backend is 'gpu' but taichi found no CUDA or Vulkan device; "
            "set score.backend to 'auto' or 'cpu'"
        )
    _TI_STATE.update(backend=backend, arch=arch)
    return arch


def _tikernels():
    from scenebot.score import _tikernels as k

    return k


def _kernels():
    import taichi as ti

    k = _tikernels()

    gpu = ti.lang.impl.current_cfg().arch in (ti.cuda, ti.vulkan)
    return {
        "fill": k.fill,
        "raster": k.raster if gpu else k.raster_per_view,
        "raster_clustered": k.raster_clustered,
        "tile_bounds": k.tile_bounds,
        "cull": k.cull,
        "angles": k.angles,
        "view_sums": k.view_sums,
        "score_per_view": k.score_per_view,
        "pixel_degrees": k.pixel_degrees,
        "neighbourhood_max": k.neighbourhood_max,
        "block_min_max": k.block_min_max,
    }


def spatial_order(points: np.ndarray) -> np.ndarray:
    """Indices that sort points along a Z-order (Morton) curve of their bounding box, so that
    consecutive points lie close together.

    Args:
        points: (N, 3) positions (m).

    Returns:
        (N,) permutation (stable for equal codes).
    """
    p = np.asarray(points, np.float64).reshape(-1, 3)
    if len(p) == 0:
        return np.zeros(0, np.int64)
    lo = p.min(axis=0)
    span = max(float((p.max(axis=0) - lo).max()), 1e-12)
    q = np.clip(((p - lo) / span * 1023.0).astype(np.int64), 0, 1023)
    code = np.zeros(len(p), np.int64)
    for bit in range(10):
        for axis in range(3):
            code |= ((q[:, axis] >> bit) & 1) << (3 * bit + axis)
    return np.argsort(code, kind="stable")


def cluster_spheres(spheres: np.ndarray, size: int) -> np.ndarray:
    """Bounding spheres of groups of ``size`` consecutive spheres.

    Args:
        spheres: (T, 4) centres and radii (m).
        size: spheres per group (the last group may hold fewer).

    Returns:
        (ceil(T / size), 4) centres (the middle of the group's centres' bounding box) and radii
        that enclose every sphere of the group, loosened by 0.1 % + 10 um so that float
        rounding never culls a group that holds a triangle the per-triangle test keeps.
    """
    s = np.asarray(spheres, np.float64).reshape(-1, 4)
    n = -(-len(s) // size)
    out = np.zeros((n, 4))
    for c in range(n):
        g = s[c * size : (c + 1) * size]
        centre = 0.5 * (g[:, :3].min(axis=0) + g[:, :3].max(axis=0))
        out[c, :3] = centre
        out[c, 3] = (np.linalg.norm(g[:, :3] - centre, axis=1) + g[:, 3]).max() * 1.001 + 1e-5
    return out


def projection_rows(views: np.ndarray) -> np.ndarray:
    """Rows of the 3x4 projection ``K [R | t]`` of each view, row-major.

    Args:
        views: (S, 19) packed views.

    Returns:
        (S, 12) float32: (u*z, v*z, z) = rows . (X, 1) for a world point X (m).
    """
    v = np.asarray(views, np.float64)
    S = v.shape[0]
    R = v[:, :9].reshape(S, 3, 3)
    Rt = np.concatenate([R, v[:, 9:12, None]], axis=2)  # (S, 3, 4)
    K = np.zeros((S, 3, 3))
    K[:, 0, 0], K[:, 1, 1], K[:, 0, 2], K[:, 1, 2], K[:, 2, 2] = (
        v[:, 15],
        v[:, 16],
        v[:, 17],
        v[:, 18],
        1.0,
    )
    return np.ascontiguousarray((K @ Rt).reshape(S, 12), dtype=np.float32)


def frustum_planes(src_views: np.ndarray, size: tuple[int, int], near: float) -> np.ndarray:
    """World-frame planes bounding each source camera's view frustum.

    Args:
        src_views: (S, 19) packed source views.
        size: (width, height) of the source images the intrinsics refer to (pixels).
        near: near distance (m).

    Returns:
        (S, 5, 4) planes ``n . X + d >= 0`` for points inside (left, right, top, bottom, near),
        loosened by 1e-4 m so that float rounding never drops a source that sees a point.
    """
    v = np.asarray(src_views, np.float64)
    S = v.shape[0]
    W, H = size
    fx, fy, cx, cy = v[:, 15], v[:, 16], v[:, 17], v[:, 18]
    z0, one = np.zeros(S), np.ones(S)
    nc = np.stack(
        [
            np.stack([fx, z0, cx], 1),
            np.stack([-fx, z0, W - cx], 1),
            np.stack([z0, fy, cy], 1),
            np.stack([z0, -fy, H - cy], 1),
            np.stack([z0, z0, one], 1),
        ],
        axis=1,
    )  # (S, 5, 3) camera frame
    nc /= np.linalg.norm(nc, axis=2, keepdims=True)
    R = v[:, :9].reshape(S, 3, 3)
    t = v[:, 9:12]
    nw = np.einsum("sji,spj->spi", R, nc)  # R^T n
    d = np.einsum("spj,sj->sp", nc, t)
    d[:, 4] -= near
    return np.concatenate([nw, (d + 1e-4)[..., None]], axis=2)


@dataclass
class ScoreResult:
    """Scores of a set of candidate views.

    Attributes:
        score_deg: (N,) mean pixel score over hit pixels (degrees); NaN when nothing is hit.
        hit_fraction: (N,) fraction of pixels whose ray hits the mesh (0..1).
        seen_fraction: (N,) fraction of hit pixels that at least one source sees (0..1).
        pixels: (N, H, W) per-pixel score (degrees, -1 = no hit), only when requested.
    """

    score_deg: np.ndarray
    hit_fraction: np.ndarray
    seen_fraction: np.ndarray
    pixels: np.ndarray | None = None


def summarize(pix: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """View score, hit and seen fractions from per-pixel scores.

    Args:
        pix: (N, H, W) pixel scores (degrees), negative where the ray hit nothing.

    Returns:
        score_deg (N,), hit_fraction (N,), seen_fraction (N,) as in :class:`ScoreResult`.
    """
    hit = pix >= 0
    n_hit = hit.sum(axis=(1, 2))
    total = np.where(hit, pix, 0.0).sum(axis=(1, 2), dtype=np.float64)
    seen = (hit & (pix < 179.999)).sum(axis=(1, 2))
    with np.errstate(invalid="ignore", divide="ignore"):
        score = np.where(n_hit > 0, total / np.maximum(n_hit, 1), np.nan)
        seen_frac = np.where(n_hit > 0, seen / np.maximum(n_hit, 1), 0.0)
    return score, n_hit / pix[0].size, seen_frac


class TaichiScorer:
    """Batched rendering-quality scorer for one map (source depth maps are made once).

    Args:
        verts: (V, 3) mesh vertices (m).
        faces: (F, 3) triangle vertex indices.
        src_views: (S, 19) packed source views (see :mod:`scenebot.score.geometry`), with the
            intrinsics of the source depth maps.
        src_size: (width, height) of the source depth maps (pixels).
        intr: intrinsics of the candidate renders.
        depth_tolerance: relative depth tolerance of the visibility test (fraction).
        near_m: near clipping distance (m).
        batch_size: candidates per launch.
        backend: ``"auto"``, ``"cpu"`` or ``"gpu"`` (see :func:`init_taichi`).
        tile_px: (width, height) of the image tiles (pixels); each tile of each candidate
            visits only the sources whose frustum can hold one of the tile's points, sorted by
            a lower bound of their angle (exact culling and early exit, for speed). Default:
            ``TILE_PX_PER_VIEW`` on the per-view pass, ``TILE_PX_BATCHED`` on the batched one.
        per_view: run every pass of a view on one thread in one launch (CPUs) rather than
            the batched passes with a thread per row, tile or chunk of triangles (GPUs).
            Default: per view on a CPU, batched on a GPU.
    """

    def __init__(
        self,
        verts: np.ndarray,
        faces: np.ndarray,
        src_views: np.ndarray,
        src_size: tuple[int, int],
        intr: Intrinsics,
        *,
        depth_tolerance: float,
        near_m: float,
        batch_size: int,
        backend: str,
        tile_px: tuple[int, int] | None = None,
        per_view: bool | None = None,
    ) -> None:
        import taichi as ti

        self.arch = init_taichi(backend)
        self.k = _kernels()
        # one thread per view on CPUs; the GPU needs a thread per pixel row, tile or chunk
        self.per_view = self.arch not in ("cuda", "vulkan") if per_view is None else per_view
        verts = np.ascontiguousarray(verts, dtype=np.float32).reshape(-1, 3)
        faces = np.ascontiguousarray(faces, dtype=np.int32).reshape(-1, 3)
        if faces.shape[0] == 0:
            raise ValueError("TaichiScorer: the mesh has no triangles")
        src_views = np.ascontiguousarray(src_views, dtype=np.float32).reshape(-1, VIEW_COLS)
        if src_views.shape[0] == 0:
            raise ValueError("TaichiScorer: no source views")
        self.intr = intr
        self.tol = float(depth_tolerance)
        self.near = float(near_m)
        self.batch = int(batch_size)
        self.n_src = src_views.shape[0]
        self.src_centres = src_views[:, 12:15].astype(np.float64)
        # triangles in Z-order of their centroids: CLUSTER consecutive ones lie close together
        # and are culled as one by the per-view rasterizer (the z-buffer, a minimum, does not
        # depend on the order)
        centroid = verts[faces].astype(np.float64).mean(axis=1)
        faces = np.ascontiguousarray(faces[spatial_order(centroid)])
        self._verts = self._to_dev(ti, verts, ti.f32)
        self._faces = self._to_dev(ti, faces, ti.i32)
        tri = verts[faces].astype(np.float64)
        centroid = tri.mean(axis=1)
        radius = np.linalg.norm(tri - centroid[:, None], axis=2).max(axis=1) * 1.001 + 1e-5
        spheres = np.column_stack([centroid, radius]).astype(np.float32)
        self._spheres = self._to_dev(ti, spheres, ti.f32)
        clusters = cluster_spheres(spheres, _tikernels().CLUSTER).astype(np.float32)
        self._clusters = self._to_dev(ti, clusters, ti.f32)
        self._src_views = self._to_dev(ti, src_views, ti.f32)
        ws, hs = src_size
        self.src_depth = ti.ndarray(ti.f32, shape=(self.n_src, hs, ws))
        self._raster(self._src_views, self.src_depth, self.n_src)
        if self.per_view:
            self._src_dmax = ti.ndarray(ti.f32, shape=(self.n_src, hs, ws))
            self.k["neighbourhood_max"](self.src_depth, self._src_dmax)
            blk = _tikernels().DMAX_BLOCK
            self._src_mm = ti.ndarray(
                ti.math.vec2, shape=(self.n_src, -(-hs // blk), -(-ws // blk))
            )
            self.k["block_min_max"](self._src_dmax, self._src_mm)
        self._src_proj = self._to_dev(ti, projection_rows(src_views), ti.f32)
        self._src_centres = ti.ndarray(ti.math.vec3, shape=(self.n_src,))
        self._src_centres.from_numpy(np.ascontiguousarray(src_views[:, 12:15]))
        planes = frustum_planes(src_views, src_size, self.near).astype(np.float32)
        self._planes = self._to_dev(ti, planes, ti.f32)
        if tile_px is None:
            tile_px = TILE_PX_PER_VIEW if self.per_view else TILE_PX_BATCHED
        self.tiles = (
            max(1, round(intr.width / max(1, tile_px[0]))),
            max(1, round(intr.height / max(1, tile_px[1]))),
        )
        n_tiles = self.tiles[0] * self.tiles[1]
        self._depth = ti.ndarray(ti.f32, shape=(self.batch, intr.height, intr.width))
        self._pix = ti.ndarray(ti.f32, shape=(self.batch, intr.height, intr.width))
        self._bounds = ti.ndarray(ti.f32, shape=(self.batch, n_tiles, 9))
        self._lists = ti.ndarray(ti.i32, shape=(self.batch, n_tiles, self.n_src))
        if self.per_view:
            self._tsrc = ti.ndarray(ti.math.vec4, shape=(self.batch, n_tiles, self.n_src))
            self._groups = ti.ndarray(ti.math.ivec2, shape=(self.batch, n_tiles, self.n_src))
            self._near_srcs = ti.ndarray(ti.i32, shape=(self.batch, 2 * self.n_src))
        else:
            self._keys = ti.ndarray(ti.f32, shape=(self.batch, n_tiles, self.n_src))
        self._n_active = ti.ndarray(ti.i32, shape=(self.batch, n_tiles))
        self._sums = ti.ndarray(ti.f32, shape=(self.batch, 3))

    @staticmethod
    def _to_dev(ti, a: np.ndarray, dtype):
        nd = ti.ndarray(dtype, shape=a.shape)
        nd.from_numpy(a)
        return nd

    def source_depth_maps(self) -> np.ndarray:
        """(S, Hs, Ws) source depth maps (m; ``FAR`` where nothing is hit)."""
        return self.src_depth.to_numpy()

    def render_depth(self, views: np.ndarray) -> np.ndarray:
        """Z-buffer of the mesh from arbitrary packed views at the candidate resolution.

        Args:
            views: (N, 19) packed views (N <= batch size).

        Returns:
            (N, H, W) depth along the camera z axis (m; ``FAR`` where nothing is hit).
        """
        n = views.shape[0]
        v32 = np.zeros((self.batch, VIEW_COLS), dtype=np.float32)
        v32[:n] = views
        v32[n:] = views[0]
        self._raster(v32, self._depth, n)
        return self._depth.to_numpy()[:n]

    def _render(self, views32: np.ndarray) -> None:
        self._raster(views32, self._depth, len(views32))

    def _n_tasks(self, n: int) -> int:
        """Parallel tasks of a per-view kernel over n views (see ``_tikernels.task_view``):
        blocks of 512 tasks, one per ``VIEWS_PER_BLOCK`` views and at least one per thread."""
        import taichi as ti

        threads = max(1, ti.lang.impl.current_cfg().cpu_max_num_threads)
        return max(n, 512 * max(threads, -(-n // VIEWS_PER_BLOCK)))

    def _raster(self, views32, depth, n: int) -> None:
        """Z-buffers of the first n views into ``depth`` (all of it on the batched path)."""
        if self.per_view:
            self.k["raster_clustered"](
                self._verts, self._faces, self._spheres, self._clusters, views32, depth, n,
                self._n_tasks(n), self.near,
            )  # fmt: skip
        else:
            self.k["fill"](depth, FAR)
            self.k["raster"](self._verts, self._faces, self._spheres, views32, depth, self.near)

    def score(self, poses: np.ndarray, return_pixels: bool = False) -> ScoreResult:
        """Score planar candidate poses.

        Args:
            poses: (N, 3) candidates (x m, y m, theta rad), camera at height z = 0.
            return_pixels: also return the (N, H, W) per-pixel scores.

        Returns:
            The scores.
        """
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        return self.score_views(candidate_views(poses, self.intr), return_pixels)

    def score_views(self, views: np.ndarray, return_pixels: bool = False) -> ScoreResult:
        """Score arbitrary packed candidate views (N, 19) with the candidate intrinsics."""
        n = views.shape[0]
        outs, sums = [], []
        for s in range(0, n, self.batch):
            v = views[s : s + self.batch]
            m = v.shape[0]
            v32 = np.zeros((self.batch, VIEW_COLS), dtype=np.float32)
            v32[:m] = v
            v32[m:] = v[0]
            tx, ty = self.tiles
            if self.per_view:
                self.k["score_per_view"](
                    self._verts, self._faces, self._spheres, self._clusters, v32, m,
                    self._n_tasks(m), self.near,
                    self._depth, tx, ty, self._bounds, self._src_centres, self._planes,
                    self._near_srcs, self._lists, self._tsrc, self._groups, self._n_active,
                    self._src_proj, self._src_dmax, self._src_mm, self.tol, self._pix,
                    self._sums,
                )  # fmt: skip
                sums.append(self._sums.to_numpy()[:m].astype(np.float64))
                if return_pixels:
                    self.k["pixel_degrees"](self._pix, m)
                    outs.append(self._pix.to_numpy()[:m])
                continue
            self._render(v32)
            self.k["tile_bounds"](self._depth, v32, tx, ty, self._bounds)
            self.k["cull"](
                self._bounds,
                v32,
                self._src_centres,
                self._planes,
                self._lists,
                self._keys,
                self._n_active,
            )
            self.k["angles"](
                self._depth,
                v32,
                self._src_proj,
                self._src_centres,
                self.src_depth,
                tx,
                ty,
                self._lists,
                self._keys,
                self._n_active,
                self.tol,
                self.near,
                self._pix,
            )
            self.k["view_sums"](self._pix, self._sums)
            sums.append(self._sums.to_numpy()[:m].astype(np.float64))
            if return_pixels:
                outs.append(self._pix.to_numpy()[:m])
        sums_a = np.concatenate(sums, axis=0) if sums else np.zeros((0, 3))
        n_pix = self.intr.width * self.intr.height
        hits = sums_a[:, 1]
        with np.errstate(invalid="ignore", divide="ignore"):
            score = np.where(hits > 0, sums_a[:, 0] / np.maximum(hits, 1), np.nan)
            seen = np.where(hits > 0, sums_a[:, 2] / np.maximum(hits, 1), 0.0)
        pix = np.concatenate(outs, axis=0) if return_pixels and outs else None
        return ScoreResult(score, hits / n_pix, seen, pix)


def source_views_for_depth(
    R: np.ndarray, t: np.ndarray, intrinsics: list[Intrinsics], depth_width: int
) -> tuple[np.ndarray, tuple[int, int]]:
    """Packed source views at depth-map resolution.

    All sources' depth maps share one size: that of the first camera scaled to
    ``depth_width``; every source's own intrinsics are scaled to that size.

    Args:
        R: (S, 3, 3) cam_from_world rotations.
        t: (S, 3) translations (m).
        intrinsics: (S,) native intrinsics.
        depth_width: depth map width (pixels).

    Returns:
        (S, 19) packed views and the (width, height) of the depth maps.
    """
    first = intrinsics[0].scaled(depth_width)
    size = (first.width, first.height)
    scaled = [k.scaled(size[0], size[1]) for k in intrinsics]
    return pack_views(R, t, scaled), size
