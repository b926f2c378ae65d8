"""The geometric proxy of view synthesis: the dense cloud splatted into a view, holes filled.

Each point of the fused cloud becomes a disc (splat) whose world radius is its distance to its
k-th neighbour, so its size on screen shrinks with depth; with ``oriented_splats`` the depth
across the disc follows the point's normal. A z-buffer (atomic minimum, taichi) keeps the
nearest surface. Holes between splats are filled by interpolating inverse depth from nearby
pixels with a push-pull pyramid (paper section V.C: "We handle holes in the rasterized point
cloud by interpolating the depths from nearby pixels").
"""

import json
import logging
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import taichi as ti
from scipy.spatial import cKDTree

from scenebot.tour.camera import Camera, TourInputError
from scenebot.tour.config import ProxyConfig

LOG = logging.getLogger(__name__)
BIG = 1e30  # "no surface" depth in the z-buffer


@dataclass
class PointProxy:
    """The dense cloud prepared for splatting.

    Attributes:
        points: (N, 3) float32 positions, metres (robot/map frame).
        normals: (N, 3) float32 unit normals.
        colors: (N, 3) uint8 RGB colours (for the overview map).
        radius: (N,) float32 splat radius, metres.
    """

    points: np.ndarray
    normals: np.ndarray
    colors: np.ndarray
    radius: np.ndarray

    def __len__(self) -> int:
        return len(self.points)

    def transformed(self, scale: float, R: np.ndarray, t: np.ndarray) -> "PointProxy":
        """The proxy moved by the similarity ``x -> scale * R @ x + t`` (another frame of the
        same scene): positions and splat radii scaled, normals turned; the points and their
        neighbours are those of this proxy (nothing is filtered or sized again)."""
        R = np.asarray(R, np.float64)
        pts = scale * self.points.astype(np.float64) @ R.T + np.asarray(t, np.float64)
        return PointProxy(
            points=pts.astype(np.float32),
            normals=(self.normals.astype(np.float64) @ R.T).astype(np.float32),
            colors=self.colors,
            radius=(abs(scale) * self.radius.astype(np.float64)).astype(np.float32),
        )

    def drop_near(self, centers: np.ndarray, radius_m: float) -> "PointProxy":
        """Remove points within ``radius_m`` of any camera centre (metres).

        The cameras stood there, so no surface can be that close: such points are fusion
        artefacts (depth estimates collapsing towards a neighbouring camera).

        Args:
            centers: (S, 3) camera centres, metres.
            radius_m: clearance, metres (<= 0: keep all).
        """
        if radius_m <= 0 or len(centers) == 0:
            return self
        d, _ = cKDTree(np.asarray(centers, np.float64)).query(
            self.points.astype(np.float64), workers=-1
        )
        keep = d >= radius_m
        return PointProxy(
            self.points[keep], self.normals[keep], self.colors[keep], self.radius[keep]
        )


def build_proxy(
    points: np.ndarray,
    normals: np.ndarray | None,
    colors: np.ndarray | None,
    cfg: ProxyConfig,
    source: str = "the dense cloud",
) -> PointProxy:
    """Validate a cloud and size its splats.

    Args:
        points: (N, 3) positions, metres.
        normals: (N, 3) normals or None (estimated from neighbours).
        colors: (N, 3) uint8 or float colours in [0, 1], or None (grey).
        cfg: proxy settings.
        source: name of the cloud for error messages (a file path).

    Returns:
        The proxy.

    Raises:
        TourInputError: fewer than ``cfg.min_points`` finite points.
    """
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    ok = np.all(np.isfinite(pts), axis=1)
    if ok.sum() < cfg.min_points:
        raise TourInputError(
            f"{source}: {int(ok.sum())} finite points, the tour needs at least "
            f"{cfg.min_points} (tour.proxy.min_points) to use the cloud as a rendering proxy; "
            "re-run the dense stage with more views (dense.max_views) or looser fusion limits"
        )
    pts = pts[ok]
    k = min(cfg.spacing_knn, len(pts) - 1)
    kq = min(max(k + 1, 9), len(pts))  # the point itself and its nearest neighbours
    m = cfg.outlier_min_neighbors
    filtering = cfg.outlier_radius > 0 and m > 0
    tree = cKDTree(pts)
    if not filtering:
        dist, idx = _knn(tree, pts, kq)
    else:
        sample = pts[:: max(1, len(pts) // 20000)]
        radius = cfg.outlier_radius * float(np.median(tree.query(sample, k=k + 1)[0][:, k]))
        # One k-nearest query serves the outlier test and the splat sizes, on both cores: "m
        # others within r" is "the m-th nearest other point within r", the ball query's test;
        # the neighbours among the points kept come from the same query (a ball query, a
        # second tree and a second query took 3x as long on a campaign's 3.8 million points)
        need = min(max(kq, m + 1), len(pts))
        dense, near = _outliers_and_neighbours(tree, pts, need, m, radius)
        if dense.sum() < cfg.min_points:
            raise TourInputError(
                f"{source}: only {int(dense.sum())} of {len(pts)} points have "
                f"{cfg.outlier_min_neighbors} neighbours within {radius:.3f} m; the cloud is too "
                f"sparse for a proxy (needs tour.proxy.min_points={cfg.min_points}): lower "
                "tour.proxy.outlier_min_neighbors or re-run the dense stage"
            )
        keep = np.flatnonzero(ok)[dense]
        ok = np.zeros_like(ok)
        ok[keep] = True
        dist, idx = _neighbours_among(pts, dense, near, kq)
        pts = pts[dense]
    k = min(k, len(pts) - 1)
    spacing = dist[:, k]
    # guard against isolated points: at most 4x the median spacing
    spacing = np.minimum(spacing, 4 * np.median(spacing))
    if normals is None or len(normals) != len(ok):
        nrm = _pca_normals(pts, idx)
    else:
        nrm = np.asarray(normals, np.float64)[ok]
        bad = ~(np.linalg.norm(nrm, axis=1) > 0.5)
        if bad.any():
            nrm[bad] = _pca_normals(pts, idx)[bad]
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)
    if colors is None or len(colors) != len(ok):
        col = np.full((len(pts), 3), 160, np.uint8)
    else:
        c = np.asarray(colors)[ok]
        col = (
            c.astype(np.uint8)
            if c.dtype == np.uint8
            else np.clip(c * 255 + 0.5, 0, 255).astype(np.uint8)
        )
    return PointProxy(
        points=pts.astype(np.float32),
        normals=nrm.astype(np.float32),
        colors=col,
        radius=(cfg.splat_scale * spacing).astype(np.float32),
    )


CHUNK = 200_000
"""Points per k-nearest query (bounds the memory of the query's (chunk, k) arrays)."""


def _knn(tree: cKDTree, pts: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` nearest points of each point (itself first): distances, indices."""
    dist, idx = np.empty((len(pts), k)), np.empty((len(pts), k), np.int64)
    for a in range(0, len(pts), CHUNK):
        dist[a : a + CHUNK], idx[a : a + CHUNK] = tree.query(pts[a : a + CHUNK], k=k, workers=-1)
    return dist, idx


def _outliers_and_neighbours(
    tree: cKDTree, pts: np.ndarray, need: int, m: int, radius: float
) -> tuple[np.ndarray, np.ndarray]:
    """Per point: whether ``m`` others lie within ``radius`` (the ``m``-th nearest other),
    and its ``need`` nearest points (int32 indices, by distance; the point first)."""
    dense = np.zeros(len(pts), bool)
    near = np.empty((len(pts), need), np.int32)
    for a in range(0, len(pts), CHUNK):
        d, i = tree.query(pts[a : a + CHUNK], k=need, workers=-1)
        if m < need:
            dense[a : a + CHUNK] = d[:, m] <= radius
        near[a : a + CHUNK] = i
    return dense, near


def _neighbours_among(
    pts: np.ndarray, kept: np.ndarray, near: np.ndarray, kq: int
) -> tuple[np.ndarray, np.ndarray]:
    """The ``kq`` nearest neighbours (the point first) of each kept point among the kept
    points, from its nearest points among all (``near``, sorted by distance): where at least
    ``kq`` of those are kept they are exactly the nearest kept ones; the other points are
    queried again among the kept points.

    Returns:
        (n_kept, kq) distances and indices into the kept points.
    """
    new_index = np.cumsum(kept) - 1
    rows = np.flatnonzero(kept)
    dist, idx = np.empty((len(rows), kq)), np.empty((len(rows), kq), np.int64)
    short = []
    for a in range(0, len(rows), CHUNK):
        r = rows[a : a + CHUNK]
        nb = near[r]
        inside = kept[nb]
        order = np.argsort(~inside, axis=1, kind="stable")[:, :kq]
        nb = np.take_along_axis(nb, order, axis=1)
        dist[a : a + CHUNK] = np.sqrt(((pts[nb] - pts[r, None]) ** 2).sum(axis=2))
        idx[a : a + CHUNK] = new_index[nb]
        short.append(a + np.flatnonzero(inside.sum(axis=1) < kq))
    short = np.concatenate(short) if short else np.zeros(0, np.int64)
    if len(short):
        sub = pts[kept]
        kk = min(kq, len(sub))
        dist[short, :kk], idx[short, :kk] = cKDTree(sub).query(sub[short], k=kk, workers=-1)
    return dist, idx


def _pca_normals(pts: np.ndarray, idx: np.ndarray) -> np.ndarray:
    nb = pts[idx] - pts[idx].mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", nb, nb)
    _, vec = np.linalg.eigh(cov)
    return vec[:, :, 0]


#: the settings :func:`build_proxy` reads (a prepared proxy records them)
BUILD_SETTINGS = ("min_points", "spacing_knn", "outlier_radius", "outlier_min_neighbors",
                  "splat_scale")  # fmt: skip
_ARRAYS = ("points", "normals", "colors", "radius")


def save_proxy(proxy: PointProxy, path: str | Path, cfg: ProxyConfig, source: str) -> Path:
    """Write a prepared proxy (``final/tour/proxy.npz``, the proxy rule): its arrays, the
    settings it was built with and the cloud it came from, so that the tour and the score
    validity load it in a second instead of each building it again (tens of seconds for a
    campaign's millions of points). Written to a temporary name, then renamed: a killed run
    leaves no half file under the name."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".part")
    settings = {k: getattr(cfg, k) for k in BUILD_SETTINGS}
    with tmp.open("wb") as fh:
        np.savez(
            fh,
            **{k: getattr(proxy, k) for k in _ARRAYS},
            settings=np.array(json.dumps(settings, sort_keys=True)),
            source=np.array(str(source)),
        )
    tmp.replace(path)
    return path


def read_proxy(path: str | Path, cfg: ProxyConfig | None = None) -> PointProxy:
    """Read a proxy :func:`save_proxy` wrote.

    Args:
        path: the ``.npz`` file.
        cfg: the settings the caller would build with: a proxy built with other ones is
            used, with a warning that names the settings (re-run the proxy rule).

    Raises:
        TourInputError: missing file, or not a proxy (arrays missing or of unequal length).
    """
    path = Path(path)
    if not path.is_file():
        raise TourInputError(f"{path}: no prepared proxy here; run the proxy rule first")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in _ARRAYS}
            settings = json.loads(str(data["settings"]))
    except (KeyError, ValueError, OSError) as err:
        raise TourInputError(
            f"{path}: not a proxy written by `python -m scenebot proxy` ({err}); build it "
            "again from the dense cloud"
        ) from err
    n = len(arrays["points"])
    if any(len(a) != n for a in arrays.values()):
        raise TourInputError(f"{path}: its arrays differ in length; build the proxy again")
    if cfg is not None:
        changed = [k for k in BUILD_SETTINGS if settings.get(k) != getattr(cfg, k)]
        if changed:
            LOG.warning(
                "%s was built with other tour.proxy settings (%s); using it as it is: re-run "
                "the proxy rule to apply them", path, ", ".join(changed),
            )  # fmt: skip
    return PointProxy(**arrays)


def load_proxy(ply_path: str | Path, cfg: ProxyConfig) -> PointProxy:
    """The proxy of a cloud: a prepared one (``.npz``, :func:`save_proxy`) as it is, or a PLY
    cloud (COLMAP's ``fused.ply``: positions, normals, colours) built into one.

    Raises:
        TourInputError: missing, unreadable, empty or too small cloud.
    """
    path = Path(ply_path)
    if path.suffix == ".npz":
        return read_proxy(path, cfg)
    if not path.is_file():
        raise TourInputError(f"{path}: no dense cloud here; run the dense stage first")
    import open3d as o3d

    pcd = o3d.io.read_point_cloud(str(path))
    pts = np.asarray(pcd.points)
    nrm = np.asarray(pcd.normals) if pcd.has_normals() else None
    col = np.asarray(pcd.colors) if pcd.has_colors() else None
    return build_proxy(pts, nrm, col, cfg, source=str(path))


# --------------------------------------------------------------------------- taichi kernels
@ti.func
def project_px(x, y, z, cam: ti.template(), c):
    """Pixel coordinates of a camera-frame point; ``cam[c, 0:8]`` = fx fy cx cy k1 k2 p1 p2."""
    xn = x / z
    yn = y / z
    r2 = xn * xn + yn * yn
    rad = 1.0 + cam[c, 4] * r2 + cam[c, 5] * r2 * r2
    xd = xn * rad + 2.0 * cam[c, 6] * xn * yn + cam[c, 7] * (r2 + 2.0 * xn * xn)
    yd = yn * rad + cam[c, 6] * (r2 + 2.0 * yn * yn) + 2.0 * cam[c, 7] * xn * yn
    return ti.math.vec2(cam[c, 0] * xd + cam[c, 2], cam[c, 1] * yd + cam[c, 3])


@ti.kernel
def _clear(buf: ti.types.ndarray(dtype=ti.f32, ndim=2), value: ti.f32):
    for i, j in buf:
        buf[i, j] = value


@ti.kernel
def _splat(
    pts: ti.types.ndarray(dtype=ti.f32, ndim=2),
    nrm: ti.types.ndarray(dtype=ti.f32, ndim=2),
    rad: ti.types.ndarray(dtype=ti.f32, ndim=1),
    pose: ti.types.ndarray(dtype=ti.f32, ndim=2),
    cam: ti.types.ndarray(dtype=ti.f32, ndim=2),
    zbuf: ti.types.ndarray(dtype=ti.f32, ndim=2),
    max_px: ti.f32,
    near: ti.f32,
    oriented: ti.i32,
):
    """z-buffer the splats; ``pose`` (3, 4) = [R | t] cam_from_world, ``cam`` (1, 8)."""
    H = zbuf.shape[0]
    W = zbuf.shape[1]
    for n in range(pts.shape[0]):
        p = ti.math.vec3(pts[n, 0], pts[n, 1], pts[n, 2])
        q = ti.math.vec3(nrm[n, 0], nrm[n, 1], nrm[n, 2])
        xc = ti.math.vec3(0.0, 0.0, 0.0)
        nc = ti.math.vec3(0.0, 0.0, 0.0)
        for r in ti.static(range(3)):
            xc[r] = pose[r, 0] * p[0] + pose[r, 1] * p[1] + pose[r, 2] * p[2] + pose[r, 3]
            nc[r] = pose[r, 0] * q[0] + pose[r, 1] * q[1] + pose[r, 2] * q[2]
        z = xc[2]
        if z > near:
            uv = project_px(xc[0], xc[1], z, cam, 0)
            r_px = ti.min(ti.max(rad[n] * cam[0, 0] / z, 0.75), max_px)
            ndx = nc.dot(xc)
            dz_max = 3.0 * rad[n]  # depth change allowed across the splat, metres
            u0 = ti.max(int(ti.floor(uv[0] - r_px)), 0)
            u1 = ti.min(int(ti.floor(uv[0] + r_px)), W - 1)
            v0 = ti.max(int(ti.floor(uv[1] - r_px)), 0)
            v1 = ti.min(int(ti.floor(uv[1] + r_px)), H - 1)
            for vv in range(v0, v1 + 1):
                for uu in range(u0, u1 + 1):
                    du = uu + 0.5 - uv[0]
                    dv = vv + 0.5 - uv[1]
                    if du * du + dv * dv <= r_px * r_px:
                        zz = z
                        if oriented:
                            rx = (uu + 0.5 - cam[0, 2]) / cam[0, 0]
                            ry = (vv + 0.5 - cam[0, 3]) / cam[0, 1]
                            den = nc[0] * rx + nc[1] * ry + nc[2]
                            if ti.abs(den) > 0.05 * ti.sqrt(rx * rx + ry * ry + 1.0):
                                zz = ti.min(ti.max(ndx / den, z - dz_max), z + dz_max)
                        if zz > near:
                            ti.atomic_min(zbuf[vv, uu], zz)


class Splatter:
    """Renders z-depth maps of a :class:`PointProxy` from any camera (taichi kernels).

    Args:
        proxy: the cloud.
        cfg: proxy settings.
    """

    def __init__(self, proxy: PointProxy, cfg: ProxyConfig):
        self.cfg = cfg
        self.n = len(proxy)
        self._pts = ti.ndarray(ti.f32, (self.n, 3))
        self._pts.from_numpy(np.ascontiguousarray(proxy.points, np.float32))
        self._nrm = ti.ndarray(ti.f32, (self.n, 3))
        self._nrm.from_numpy(np.ascontiguousarray(proxy.normals, np.float32))
        self._rad = ti.ndarray(ti.f32, (self.n,))
        self._rad.from_numpy(np.ascontiguousarray(proxy.radius, np.float32))
        self._bufs: dict[tuple[int, int], ti.Ndarray] = {}

    def raw_depth(
        self, cam: Camera, R: np.ndarray, t: np.ndarray, max_px: float | None = None
    ) -> np.ndarray:
        """Splatted z-depth without hole filling.

        Args:
            cam: the camera.
            R: (3, 3) cam_from_world rotation.
            t: (3,) cam_from_world translation, metres.
            max_px: largest splat radius, pixels (default: ``max_splat_px`` scaled to the
                image width).

        Returns:
            (H, W) float32 z-depth, metres; ``inf`` where no splat lands.
        """
        shape = (cam.height, cam.width)
        if shape not in self._bufs:
            self._bufs[shape] = ti.ndarray(ti.f32, shape)
        buf = self._bufs[shape]
        _clear(buf, BIG)
        pose = np.concatenate([np.asarray(R), np.asarray(t).reshape(3, 1)], 1).astype(np.float32)
        if max_px is None:
            max_px = self.cfg.max_splat_px * cam.width / 640.0
        _splat(
            self._pts,
            self._nrm,
            self._rad,
            pose,
            cam.as_array()[None],
            buf,
            max(max_px, 0.75),
            self.cfg.near_m,
            int(self.cfg.oriented_splats),
        )
        z = buf.to_numpy()
        z[z >= BIG * 0.5] = np.inf
        return z

    def depth(self, cam: Camera, R: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Proxy z-depth of a view: splats, occlusion clean-up and hole filling.

        Returns:
            (H, W) float32 z-depth, metres; ``inf`` where holes are too large to fill.
        """
        z = self.raw_depth(cam, R, t)
        min_px = round(self.cfg.min_blob_px * cam.width * cam.height / (640 * 480))
        z = remove_small_blobs(z, min_px)
        win = self.cfg.occlusion_window_px
        if win > 0:
            win = max(5, round(win * cam.width / 640))
        z = remove_occluded(z, win, self.cfg.occlusion_rel_depth)
        return fill_holes(z, self.cfg.hole_fill_levels)


def remove_small_blobs(z: np.ndarray, min_px: int) -> np.ndarray:
    """Drop connected patches of splatted pixels smaller than ``min_px`` pixels.

    Args:
        z: (H, W) z-depth, metres (``inf`` = empty).
        min_px: smallest patch kept, pixels (<= 1: do nothing).

    Returns:
        (H, W) float32 z-depth with the small patches set to ``inf``.
    """
    if min_px <= 1:
        return z
    valid = np.isfinite(z).astype(np.uint8)
    _, labels, stats, _ = cv2.connectedComponentsWithStats(valid, connectivity=8)
    small = stats[:, cv2.CC_STAT_AREA] < min_px
    small[0] = False  # background label
    if not small[1:].any():
        return z
    out = z.copy()
    out[small[labels] & (valid > 0)] = np.inf
    return out


def remove_occluded(z: np.ndarray, window_px: int, rel_depth: float) -> np.ndarray:
    """Turn into holes the pixels that see far surfaces through gaps between near splats.

    A pixel is dropped if it is deeper than ``(1 + rel_depth)`` times the nearest depth in a
    ``window_px`` square around it *and* that nearer surface surrounds it (nearer depth found
    on both sides horizontally or vertically), so true depth edges are kept.

    Args:
        z: (H, W) z-depth, metres (``inf`` = empty).
        window_px: window side, pixels (0 = do nothing).
        rel_depth: relative depth step (fraction).

    Returns:
        (H, W) float32 z-depth with the dropped pixels set to ``inf``.
    """
    if window_px <= 1:
        return z
    zf = np.where(np.isfinite(z), z, BIG).astype(np.float32)
    h = window_px // 2
    sides = []
    for kx in ((h + 1, 1), (1, h + 1)):
        k = cv2.getStructuringElement(cv2.MORPH_RECT, kx)
        a = cv2.erode(zf, k, anchor=(kx[0] - 1, kx[1] - 1), borderValue=BIG)  # min left/up
        b = cv2.erode(zf, k, anchor=(0, 0), borderValue=BIG)  # min right/down
        sides.append(np.maximum(a, b))
    near = np.minimum(sides[0], sides[1])
    occluded = np.isfinite(z) & (zf > near * (1 + rel_depth))
    out = z.copy()
    out[occluded] = np.inf
    return out


def _scanline_fill(z: np.ndarray, step_rel: float) -> np.ndarray:
    """Fill holes along rows from the nearest valid pixels left and right.

    Inverse depth is interpolated linearly (exact for a plane); where the two ends differ by
    more than ``step_rel`` (a depth edge), the hole takes the farther end: a hole next to an
    object is most often the background surface continuing behind it.

    Args:
        z: (H, W) z-depth (``inf`` = empty).
        step_rel: relative depth difference treated as an edge (fraction).

    Returns:
        (H, W) float32 z-depth; rows' holes without a valid pixel on both sides stay empty.
    """
    H, W = z.shape
    valid = np.isfinite(z)
    cols = np.broadcast_to(np.arange(W), (H, W))
    left = np.maximum.accumulate(np.where(valid, cols, -1), axis=1)
    right = np.minimum.accumulate(np.where(valid, cols, W)[:, ::-1], axis=1)[:, ::-1]
    hole = ~valid & (left >= 0) & (right < W)
    if not hole.any():
        return z
    ii, jj = np.nonzero(hole)
    lj, rj = left[ii, jj], right[ii, jj]
    zl, zr = z[ii, lj], z[ii, rj]
    a = (jj - lj) / (rj - lj)
    inv = (1 - a) / zl + a / zr
    edge = np.abs(zl - zr) > step_rel * np.minimum(zl, zr)
    out = z.copy()
    out[ii, jj] = np.where(edge, np.maximum(zl, zr), 1.0 / inv)
    return out


def fill_holes(z: np.ndarray, levels: int, step_rel: float = 0.2) -> np.ndarray:
    """Interpolate depth into empty pixels: along rows, then columns, then a push-pull pyramid.

    Rows first: the captured rooms are mostly vertical planes (walls, furniture sides) seen by
    a level camera, whose depth along a row is linear in inverse depth; then columns for holes
    touching the image's left or right border; then the push-pull pyramid for the rest.

    Push-pull: each coarser level averages the valid inverse depths of 2x2 blocks (weights =
    valid counts); each empty pixel takes the bilinearly upsampled coarser value. Holes
    wider than about ``2**levels`` pixels stay empty.

    Args:
        z: (H, W) z-depth, metres (``inf`` = empty).
        levels: pyramid levels (0 = no filling at all).
        step_rel: relative depth difference treated as an edge by the row/column pass.

    Returns:
        (H, W) float32 z-depth.
    """
    valid = np.isfinite(z) & (z > 0)
    if levels <= 0 or valid.all() or not valid.any():
        return z.astype(np.float32)
    z = _scanline_fill(np.where(valid, z, np.inf).astype(np.float32), step_rel)
    z = _scanline_fill(z.T, step_rel).T
    valid = np.isfinite(z)
    if valid.all():
        return z.astype(np.float32)
    inv = np.where(valid, 1.0 / np.where(valid, z, 1.0), 0.0).astype(np.float32)
    w = valid.astype(np.float32)
    pyr = [(inv * w, w)]
    for _ in range(levels):
        s, c = pyr[-1]
        if min(s.shape) < 2:
            break
        h2, w2 = s.shape[0] // 2 * 2, s.shape[1] // 2 * 2
        s2 = s[:h2:2, :w2:2] + s[1:h2:2, :w2:2] + s[:h2:2, 1:w2:2] + s[1:h2:2, 1:w2:2]
        c2 = c[:h2:2, :w2:2] + c[1:h2:2, :w2:2] + c[:h2:2, 1:w2:2] + c[1:h2:2, 1:w2:2]
        # normalise to a weight in [0, 1] so the coarse value is a plain average
        val = np.where(c2 > 0, s2 / np.maximum(c2, 1e-12), 0.0).astype(np.float32)
        pyr.append((val * (c2 > 0), (c2 > 0).astype(np.float32)))
    # pull: from coarse to fine, fill what is empty
    val = np.where(pyr[-1][1] > 0, pyr[-1][0] / np.maximum(pyr[-1][1], 1e-12), 0.0)
    have = pyr[-1][1] > 0
    for s, c in reversed(pyr[:-1]):
        shape = (s.shape[1], s.shape[0])
        up_v = cv2.resize((val * have).astype(np.float32), shape, interpolation=cv2.INTER_LINEAR)
        up_w = cv2.resize(have.astype(np.float32), shape, interpolation=cv2.INTER_LINEAR)
        fine = np.where(c > 0, s / np.maximum(c, 1e-12), 0.0)
        coarse = np.where(up_w > 1e-3, up_v / np.maximum(up_w, 1e-3), 0.0)
        val = np.where(c > 0, fine, coarse)
        have = (c > 0) | (up_w > 1e-3)
    out = np.full(z.shape, np.inf, np.float32)
    ok = have & (val > 0)
    out[ok] = 1.0 / val[ok]
    return out
