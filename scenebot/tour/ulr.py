"""Unstructured lumigraph rendering (Buehler et al., SIGGRAPH 2001) on a point-cloud proxy.

For a novel view, the proxy (:mod:`scenebot.tour.proxy`) gives each pixel a surface point
``P``. For every source photo ``i`` that sees ``P`` (inside its image, and not occluded: the
proxy's depth rendered into the source agrees with ``P``'s depth there), the penalty

    p_i = a * angle(P - C_i, P - C) + b * max(0, |P - C_i| - |P - C|) / |P - C| + g * fov_i

combines the angle between the source's and the novel ray (radians), the resolution loss
of a source farther from the surface, and a field-of-view term that rises towards the
source's image border. The k best sources get the ULR weights
``w_i = (1 - p_i / p_(k+1)) / (p_i + eps)`` (zero at the (k+1)-th best penalty so sources
enter and leave the blend smoothly; the 1 / p factor makes a source at the novel view's
position reproduce its photo: epipole consistency), normalised, and their bilinearly sampled
colours are blended.

No black pixel where a photo saw the surface: a pixel whose point none of the preselected
sources sees unoccluded is blended from the other photos that see it (the next best); a
point that no photo sees takes the colour of the nearest point of the dense cloud. Only a
pixel with no proxy surface at all stays black (:attr:`RenderResult.fill` says which pixel
came from where).

The kernels run on CPU or GPU (taichi). Entry point: :class:`UlrRenderer`.
"""

import logging
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import taichi as ti

from scenebot.tour.camera import Camera, TourInputError
from scenebot.tour.config import TourConfig
from scenebot.tour.proxy import PointProxy, Splatter, project_px

LOG = logging.getLogger(__name__)
_BIGP = 1e20


@dataclass
class SourceView:
    """One registered photo.

    Attributes:
        name: image name in the model (relative to the image folder).
        camera: its camera.
        R: (3, 3) cam_from_world rotation.
        t: (3,) cam_from_world translation, metres.
        image: (H, W, 3) uint8 RGB photo.
    """

    name: str
    camera: Camera
    R: np.ndarray
    t: np.ndarray
    image: np.ndarray

    @property
    def center(self) -> np.ndarray:
        """(3,) camera centre, metres."""
        return -self.R.T @ self.t


def load_sources(rec, image_dir: str | Path) -> list[SourceView]:
    """The registered photos of a ``pycolmap.Reconstruction``, sorted by name.

    Args:
        rec: the reconstruction (robot frame, metres).
        image_dir: folder the model's image names are relative to.

    Raises:
        TourInputError: no registered image, or a photo file is missing or unreadable.
    """
    image_dir = Path(image_dir)
    out = []
    for img in sorted(rec.images.values(), key=lambda im: im.name):
        if not img.has_pose:
            continue
        path = image_dir / img.name
        bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if bgr is None:
            raise TourInputError(
                f"{path}: photo of the map missing or unreadable; the image folder must be the "
                "one the model's image names are relative to (results/{scene}/ for the robot)"
            )
        cam = Camera.from_pycolmap(rec.cameras[img.camera_id])
        if bgr.shape[:2] != (cam.height, cam.width):
            raise TourInputError(
                f"{path}: {bgr.shape[1]}x{bgr.shape[0]} pixels but its camera says "
                f"{cam.width}x{cam.height}; the photos do not belong to this model"
            )
        pose = img.cam_from_world() if callable(img.cam_from_world) else img.cam_from_world
        R = np.asarray(pose.rotation.matrix(), np.float64)
        t = np.asarray(pose.translation, np.float64)
        out.append(SourceView(img.name, cam, R, t, cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)))
    if not out:
        raise TourInputError("the sparse model has no registered image: run SfM first")
    return out


# --------------------------------------------------------------------------- taichi kernel
# The kernel's parameter vector ``prm``: the penalty weights a (angle), b (resolution) and
# g (field of view), border_px, vis_tol, eps, near and through_tol, at these indices.
_A, _B, _G, _BORDER, _VIS_TOL, _EPS, _NEAR, _THROUGH = range(8)


@ti.func
def _novel_centre(pose: ti.template()):
    """The novel camera's centre ``C = -R^T t`` (``pose`` (3, 4) = [R | t])."""
    C = ti.math.vec3(0.0, 0.0, 0.0)
    for c in ti.static(range(3)):
        C[c] = -(pose[0, c] * pose[0, 3] + pose[1, c] * pose[1, 3] + pose[2, c] * pose[2, 3])
    return C


@ti.func
def _pixel_point(rays: ti.template(), pose: ti.template(), C, i, j, z):
    """The world point of pixel (i, j) at z-depth ``z``: ``C + R^T (z * ray)``."""
    xc = ti.math.vec3(rays[i, j, 0] * z, rays[i, j, 1] * z, z)
    P = ti.math.vec3(0.0, 0.0, 0.0)
    for c in ti.static(range(3)):
        P[c] = C[c] + pose[0, c] * xc[0] + pose[1, c] * xc[1] + pose[2, c] * xc[2]
    return P


@ti.func
def _in_source(s_pose: ti.template(), s, P):
    """World point ``P`` in source ``s``'s camera frame: ``R_s P + t_s``."""
    q = ti.math.vec3(0.0, 0.0, 0.0)
    for r in ti.static(range(3)):
        q[r] = (
            s_pose[s, r, 0] * P[0]
            + s_pose[s, r, 1] * P[1]
            + s_pose[s, r, 2] * P[2]
            + s_pose[s, r, 3]
        )
    return q


@ti.func
def _border_distance(uv, s_cam: ti.template(), s):
    """Distance (pixels) of ``uv`` from the nearest border of source ``s``'s image."""
    sw = s_cam[s, 8]
    sh = s_cam[s, 9]
    return ti.min(ti.min(uv[0], sw - uv[0]), ti.min(uv[1], sh - uv[1]))


@ti.func
def _penalty(P, dT, lenT, s_pose: ti.template(), s, dist_b, prm: ti.template()):
    """The ULR penalty of source ``s`` for ``P``: a * angle + b * resolution loss + g * fov.

    ``dT = P - C`` is the novel ray, ``lenT`` its length, ``dist_b`` the distance of ``P``'s
    projection from the source's image border (pixels).
    """
    dS = P - ti.math.vec3(s_pose[s, 0, 4], s_pose[s, 1, 4], s_pose[s, 2, 4])
    lenS = dS.norm() + 1e-9
    cosang = ti.min(ti.max(dS.dot(dT) / (lenS * lenT), -1.0), 1.0)
    pen = prm[_A] * ti.acos(cosang)
    pen += prm[_B] * ti.max(0.0, lenS - lenT) / lenT
    pen += prm[_G] * ti.max(0.0, 1.0 - dist_b / prm[_BORDER])
    return pen


@ti.func
def _unoccluded(s_vis: ti.template(), s_vscale: ti.template(), s, uv, zs, vis_tol, through_tol):
    """Whether source ``s`` sees the point at its depth ``zs`` and pixel ``uv``: not farther
    than the proxy depth rendered into the source there (tolerance ``vis_tol``), and not
    nearer by more than ``through_tol`` (relative) either."""
    vx = ti.min(int(uv[0] * s_vscale[s, 0]), s_vis.shape[2] - 1)
    vy = ti.min(int(uv[1] * s_vscale[s, 1]), s_vis.shape[1] - 1)
    dvis = s_vis[s, vy, vx]
    # nothing nearer hides the point, and the source does not see a surface well behind it
    # (then the point is empty space the source looks through: a guess of the hole filling)
    return zs <= dvis * (1.0 + vis_tol) and (dvis > 1e29 or zs >= dvis * (1.0 - through_tol))


@ti.func
def _bilinear(s_img: ti.template(), s_cam: ti.template(), s, u, v):
    """Source ``s``'s colour at pixel coordinates (u, v), bilinear, clamped to the image."""
    x = u - 0.5
    y = v - 0.5
    x0 = ti.min(ti.max(int(ti.floor(x)), 0), int(s_cam[s, 8]) - 1)
    y0 = ti.min(ti.max(int(ti.floor(y)), 0), int(s_cam[s, 9]) - 1)
    x1 = ti.min(x0 + 1, int(s_cam[s, 8]) - 1)
    y1 = ti.min(y0 + 1, int(s_cam[s, 9]) - 1)
    fx = ti.min(ti.max(x - x0, 0.0), 1.0)
    fy = ti.min(ti.max(y - y0, 0.0), 1.0)
    col = ti.math.vec3(0.0, 0.0, 0.0)
    for c in ti.static(range(3)):
        top = (1 - fx) * ti.cast(s_img[s, y0, x0, c], ti.f32) + fx * ti.cast(
            s_img[s, y0, x1, c], ti.f32
        )
        bot = (1 - fx) * ti.cast(s_img[s, y1, x0, c], ti.f32) + fx * ti.cast(
            s_img[s, y1, x1, c], ti.f32
        )
        col[c] = (1 - fy) * top + fy * bot
    return col


# The best sources of a pixel are kept in four lists of a fixed length ``kk`` (k + 1, unrolled
# at compile time), sorted by penalty: ``bp`` (penalty), ``bi`` (source, -1: empty), ``bu``
# and ``bv`` (the pixel in the source).


@ti.func
def _insert_best(bp: ti.template(), bi: ti.template(), bu: ti.template(), bv: ti.template(),
                 pen, s, u, v, kk: ti.template()):  # fmt: skip
    """Insert source ``s`` (penalty ``pen``, pixel (u, v)) into the sorted lists; the worst
    one drops out."""
    cp = pen
    ci = s
    cu = u
    cv = v
    for m in ti.static(range(kk)):
        if cp < bp[m]:
            tp = bp[m]
            tq = bi[m]
            tu = bu[m]
            tv = bv[m]
            bp[m] = cp
            bi[m] = ci
            bu[m] = cu
            bv[m] = cv
            cp = tp
            ci = tq
            cu = tu
            cv = tv


@ti.func
def _rank_sources(P, C, s_pose: ti.template(), s_cam: ti.template(), s_on: ti.template(),
                  s_vis: ti.template(), s_vscale: ti.template(), prm: ti.template(),
                  bp: ti.template(), bi: ti.template(), bu: ti.template(), bv: ti.template(),
                  kk: ti.template()):  # fmt: skip
    """Fill the lists with the enabled sources that see ``P`` (novel centre ``C``)
    unoccluded, best first (none: the lists stay empty and the pixel is filled later)."""
    dT = P - C
    lenT = dT.norm() + 1e-9
    for s in range(s_pose.shape[0]):
        if s_on[s] != 0:
            q = _in_source(s_pose, s, P)
            if q[2] > prm[_NEAR]:
                uv = project_px(q[0], q[1], q[2], s_cam, s)
                dist_b = _border_distance(uv, s_cam, s)
                # inside the image, and not occluded: the proxy depth rendered into the
                # source agrees
                tol = prm[_VIS_TOL]
                if dist_b > 0.5 and _unoccluded(s_vis, s_vscale, s, uv, q[2], tol, prm[_THROUGH]):
                    pen = _penalty(P, dT, lenT, s_pose, s, dist_b, prm)
                    _insert_best(bp, bi, bu, bv, pen, s, uv[0], uv[1], kk)


@ti.func
def _threshold(bp: ti.template(), bi: ti.template(), kk: ti.template()):
    """The weights' zero: the (k+1)-th best penalty, else a bit above the worst kept one."""
    thresh = bp[kk - 1]
    if bi[kk - 1] < 0:
        worst = 0.0
        for m in ti.static(range(kk - 1)):
            if bi[m] >= 0:
                worst = ti.max(worst, bp[m])
        thresh = worst * 1.5 + 1e-3
    return thresh


@ti.func
def _blend_best(bp: ti.template(), bi: ti.template(), bu: ti.template(), bv: ti.template(),
                s_img: ti.template(), s_cam: ti.template(), prm: ti.template(),
                col: ti.template(), kk: ti.template()):  # fmt: skip
    """Add the k best sources' colours to ``col`` (zero) with the ULR weights, normalised.

    Returns:
        The number of sources with a positive weight.
    """
    thresh = _threshold(bp, bi, kk)
    wsum = 0.0
    used = 0
    for m in ti.static(range(kk - 1)):
        if bi[m] >= 0:
            w = ti.max(1.0 - bp[m] / thresh, 0.0) / (bp[m] + prm[_EPS])
            if w > 0.0:
                col += w * _bilinear(s_img, s_cam, bi[m], bu[m], bv[m])
                wsum += w
                used += 1
    if wsum > 0:
        col /= wsum
    return used


def _make_blend_kernel(k: int):
    """The ULR kernel for a fixed k (the best-k lists are unrolled at compile time)."""
    kk = k + 1

    @ti.kernel
    def blend(
        depth: ti.types.ndarray(dtype=ti.f32, ndim=2),
        rays: ti.types.ndarray(dtype=ti.f32, ndim=3),
        pose: ti.types.ndarray(dtype=ti.f32, ndim=2),
        s_pose: ti.types.ndarray(dtype=ti.f32, ndim=3),
        s_cam: ti.types.ndarray(dtype=ti.f32, ndim=2),
        s_on: ti.types.ndarray(dtype=ti.i32, ndim=1),
        s_img: ti.types.ndarray(dtype=ti.u8, ndim=4),
        s_vis: ti.types.ndarray(dtype=ti.f32, ndim=3),
        s_vscale: ti.types.ndarray(dtype=ti.f32, ndim=2),
        prm: ti.types.ndarray(dtype=ti.f32, ndim=1),
        out: ti.types.ndarray(dtype=ti.f32, ndim=3),
        nused: ti.types.ndarray(dtype=ti.i32, ndim=2),
    ):
        """``pose`` (3, 4) novel [R | t]; ``s_pose`` (S, 3, 5) sources [R | t | C];
        ``s_cam`` (S, 10) fx fy cx cy k1 k2 p1 p2 W H; ``s_vscale`` (S, 2) vis-map scale;
        ``prm`` = a, b, g, border_px, vis_tol, eps, near, through_tol."""
        H = depth.shape[0]
        W = depth.shape[1]
        C = _novel_centre(pose)
        for i, j in ti.ndrange(H, W):
            z = depth[i, j]
            col = ti.math.vec3(0.0, 0.0, 0.0)
            used = 0
            if z < 1e29:
                P = _pixel_point(rays, pose, C, i, j, z)
                bp = ti.Vector([_BIGP] * kk, dt=ti.f32)
                bi = ti.Vector([-1] * kk, dt=ti.i32)
                bu = ti.Vector([0.0] * kk, dt=ti.f32)
                bv = ti.Vector([0.0] * kk, dt=ti.f32)
                _rank_sources(P, C, s_pose, s_cam, s_on, s_vis, s_vscale, prm, bp, bi, bu, bv, kk)
                used = _blend_best(bp, bi, bu, bv, s_img, s_cam, prm, col, kk)
            for c in ti.static(range(3)):
                out[i, j, c] = col[c]
            nused[i, j] = used

    return blend


_KERNELS: dict[int, object] = {}


def _blend_kernel(k: int):
    if k not in _KERNELS:
        _KERNELS[k] = _make_blend_kernel(k)
    return _KERNELS[k]


# RenderResult.fill codes: how a pixel got its colour
FILL_BLEND, FILL_NEXT, FILL_PROXY, FILL_NONE = 0, 1, 2, 3


@dataclass
class RenderResult:
    """One synthesized view.

    Attributes:
        image: (H, W, 3) uint8 RGB.
        depth: (H, W) float32 proxy z-depth, metres (``inf`` = no surface).
        sources: (H, W) int32 number of blended sources per pixel.
        coverage: fraction of pixels with a proxy surface and at least one source.
        fill: (H, W) uint8 where each pixel's colour came from: ``FILL_BLEND`` (the k best
            of the preselected photos), ``FILL_NEXT`` (the next best photos that see the
            point), ``FILL_PROXY`` (no photo sees it: the dense cloud's colour) or
            ``FILL_NONE`` (no surface: black, unless inpainted).
    """

    image: np.ndarray
    depth: np.ndarray
    sources: np.ndarray
    coverage: float
    fill: np.ndarray | None = None

    @property
    def black_fraction(self) -> float:
        """Fraction of pixels that got no colour (``FILL_NONE``)."""
        if self.fill is None:
            return float((self.sources == 0).mean())
        return float((self.fill == FILL_NONE).mean())

    def fill_fractions(self) -> dict[str, float]:
        """Fractions of pixels per fill code: ``blend``, ``next``, ``proxy``, ``none``."""
        f = self.fill if self.fill is not None else np.where(self.sources > 0, 0, 3)
        return {
            name: float((f == code).mean())
            for name, code in (("blend", FILL_BLEND), ("next", FILL_NEXT),
                               ("proxy", FILL_PROXY), ("none", FILL_NONE))
        }  # fmt: skip


class UlrRenderer:
    """Renders novel views of a captured scene from its photos and dense cloud.

    Args:
        proxy: the dense cloud (see :func:`scenebot.tour.proxy.load_proxy`).
        sources: the registered photos (see :func:`load_sources`).
        cfg: tour settings (``cfg.proxy`` and ``cfg.ulr`` are used here).

    Taichi must be initialised first (:func:`scenebot.taichi_setup.init_taichi`).
    """

    def __init__(self, proxy: PointProxy, sources: list[SourceView], cfg: TourConfig):
        if not sources:
            raise TourInputError("no source photos to render from")
        self.cfg = cfg
        self.sources = sources
        centers = np.array([s.center for s in sources])
        proxy = proxy.drop_near(centers, cfg.proxy.camera_clearance_m)
        if len(proxy) < cfg.proxy.min_points:
            raise TourInputError(
                f"only {len(proxy)} dense points remain away from the cameras "
                f"(tour.proxy.camera_clearance_m={cfg.proxy.camera_clearance_m}); the tour needs "
                f"{cfg.proxy.min_points}: re-run the dense stage"
            )
        self.proxy = proxy
        self.splatter = Splatter(proxy, cfg.proxy)
        S = len(sources)
        Hm = max(s.camera.height for s in sources)
        Wm = max(s.camera.width for s in sources)
        img = np.zeros((S, Hm, Wm, 3), np.uint8)
        pose = np.zeros((S, 3, 5), np.float32)
        cam = np.zeros((S, 10), np.float32)
        vs = cfg.ulr.visibility_scale
        Hv, Wv = max(1, round(Hm * vs)), max(1, round(Wm * vs))
        vis = np.full((S, Hv, Wv), np.inf, np.float32)
        vscale = np.zeros((S, 2), np.float32)
        self._source_depth = np.full(S, np.nan)
        for s, src in enumerate(sources):
            h, w = src.camera.height, src.camera.width
            img[s, :h, :w] = src.image
            pose[s, :, :3] = src.R
            pose[s, :, 3] = src.t
            pose[s, :, 4] = src.center
            cam[s, :8] = src.camera.params
            cam[s, 8:] = (w, h)
            vw, vh = max(1, round(w * vs)), max(1, round(h * vs))
            # raw splats, no hole filling: only real surfaces occlude (a textureless wall
            # without points must not hide what the source photographed)
            vis[s, :vh, :vw] = self.splatter.raw_depth(src.camera.resized(vw, vh), src.R, src.t)
            vscale[s] = (vw / w, vh / h)
            centre = vis[s, vh // 4 : vh - vh // 4, vw // 4 : vw - vw // 4]
            centre = centre[np.isfinite(centre)]
            self._source_depth[s] = np.median(centre) if len(centre) else np.nan
        vis[~np.isfinite(vis)] = 1e30  # no proxy there: nothing occludes
        self._img = ti.ndarray(ti.u8, img.shape)
        self._img.from_numpy(img)
        self._vis = ti.ndarray(ti.f32, vis.shape)
        self._vis.from_numpy(vis)
        self._pose = pose
        self._cam = cam
        self._vscale = vscale
        self.centers = pose[:, :, 4].astype(np.float64)
        self._rays: dict[Camera, np.ndarray] = {}
        self._tree = None  # KD-tree of the proxy, for the colour of points no photo sees

    @property
    def num_sources(self) -> int:
        return len(self.sources)

    def source_targets(self) -> np.ndarray:
        """Where each photo looks: the dense cloud's mass in front of it.

        The point on the photo's optical axis at the median proxy depth of the central half
        of its image (the splats it sees there, no hole filling).

        Returns:
            (S, 3) points; NaN for a photo whose centre sees no dense point.
        """
        fwd = np.array([s.R[2] for s in self.sources])
        return self.centers + self._source_depth[:, None] * fwd

    def _proxy_colour(self, P: np.ndarray) -> np.ndarray:
        """(K, 3) float colours of the dense points nearest to world points (K, 3): the
        approximate nearest (within twice the nearest distance, ``eps=1``): an exact query
        from a hole-filled background far from the cloud visits most of a dense cloud's
        tree (100,000 such queries: 104 s exact, 2 s approximate on the temple's cloud)."""
        if self._tree is None:
            from scipy.spatial import cKDTree

            self._tree = cKDTree(self.proxy.points.astype(np.float64))
        _, idx = self._tree.query(np.asarray(P, np.float64), eps=1.0, workers=-1)
        return self.proxy.colors[idx].astype(np.float32)

    def _hole_colours(self, cam, R, t, depth, hole, ii, jj, step: int = 2) -> np.ndarray:
        """The cloud's colour for the hole pixels ``(ii, jj)``: looked up at the hole's pixels
        on a ``step``-pixel grid (every pixel of a hole the grid misses), each hole pixel
        taking the colour of the nearest looked-up pixel in the image."""
        sample = hole & (np.arange(hole.shape[0])[:, None] % step == 0)
        sample &= np.arange(hole.shape[1])[None, :] % step == 0
        n_lab, lab = cv2.connectedComponents(hole.astype(np.uint8), connectivity=8)
        missed = np.setdiff1d(np.arange(1, n_lab), np.unique(lab[sample]))
        if len(missed):
            sample |= np.isin(lab, missed)  # small holes between the grid's pixels
        si, sj = np.nonzero(sample)
        xc = self._rays[cam][si, sj] * depth[si, sj, None]
        P = (xc - np.asarray(t, np.float64)) @ np.asarray(R, np.float64)
        colours = self._proxy_colour(P)
        if len(si) == len(ii):
            return colours
        # nearest looked-up pixel: distance transform to the samples, labelled by pixel
        _, near = cv2.distanceTransformWithLabels(
            (~sample).astype(np.uint8), cv2.DIST_L2, 3, labelType=cv2.DIST_LABEL_PIXEL
        )
        index = np.zeros(len(si) + 1, np.int64)
        index[near[si, sj]] = np.arange(len(si))
        return colours[index[near[ii, jj]]]

    def _preselect(self, depth, cam, R, t, on, k, max_sources, step_px=16):
        """Keep the sources that can matter for this view (speed; same result in practice).

        The proxy points of a coarse pixel grid (every ``step_px``) are projected into every
        enabled source; a source is kept if it is among the k + 1 smallest angular penalties
        of some grid point that it sees inside its image. At most ``max_sources`` are kept,
        those chosen by the most grid points first.

        Returns:
            (S,) int32 enabled flags.
        """
        rays = self._rays[cam][step_px // 2 :: step_px, step_px // 2 :: step_px]
        z = depth[step_px // 2 :: step_px, step_px // 2 :: step_px]
        ok = np.isfinite(z)
        if not ok.any():
            return on
        xc = rays[ok] * z[ok, None]
        Rn = np.asarray(R, np.float64)
        C = -Rn.T @ np.asarray(t, np.float64)
        P = (xc - np.asarray(t, np.float64)) @ Rn  # world = R^T (x - t)
        idx = np.flatnonzero(on)
        sr = self._pose[idx, :, :3].astype(np.float64)
        st = self._pose[idx, :, 3].astype(np.float64)
        q = np.einsum("sij,nj->sni", sr, P) + st[:, None, :]  # (S, N, 3)
        zq = q[..., 2]
        front = zq > self.cfg.proxy.near_m
        cam_p = self._cam[idx].astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            u_ = cam_p[:, 0:1] * q[..., 0] / zq + cam_p[:, 2:3]
            v_ = cam_p[:, 1:2] * q[..., 1] / zq + cam_p[:, 3:4]
        inside = front & (u_ > 0) & (v_ > 0) & (u_ < cam_p[:, 8:9]) & (v_ < cam_p[:, 9:10])
        dS = P[None] - self.centers[idx][:, None, :]
        dT = P - C
        cosang = np.einsum("snk,nk->sn", dS, dT) / (
            np.linalg.norm(dS, axis=2) * np.linalg.norm(dT, axis=1)[None] + 1e-12
        )
        pen = np.where(inside, -cosang, np.inf)  # smaller = better
        kk = min(k + 1, len(idx))
        best = np.argpartition(pen, kk - 1, axis=0)[:kk]  # (kk, N)
        valid = np.take_along_axis(pen, best, axis=0) < np.inf
        votes = np.bincount(best[valid], minlength=len(idx))
        chosen = np.flatnonzero(votes > 0)
        chosen = chosen[np.argsort(-votes[chosen], kind="stable")][:max_sources]
        out = np.zeros_like(on)
        out[idx[chosen]] = 1
        return out

    def _enabled(self, exclude: set[int] | None, only: set[int] | None) -> np.ndarray:
        """(S,) int32 flags of the sources to use: ``only`` (all if None) less ``exclude``."""
        on = np.ones(self.num_sources, np.int32)
        if only is not None:
            on[:] = 0
            on[list(only)] = 1
        if exclude:
            on[list(exclude)] = 0
        return on

    def _kernel_params(self) -> np.ndarray:
        """The kernel's ``prm`` (float32): a, b, g, border_px, vis_tol, eps, near, through."""
        u = self.cfg.ulr
        return np.array(
            [
                u.angle_weight,
                u.resolution_weight,
                u.fov_weight,
                u.border_px,
                u.visibility_tolerance,
                u.epsilon,
                self.cfg.proxy.near_m,
                u.see_through_tolerance,
            ],
            np.float32,
        )

    def render(
        self,
        cam: Camera,
        R: np.ndarray,
        t: np.ndarray,
        exclude: set[int] | None = None,
        only: set[int] | None = None,
        k: int | None = None,
        fill: bool = True,
    ) -> RenderResult:
        """Render one view from any pose.

        Args:
            cam: camera of the novel view.
            R: (3, 3) cam_from_world rotation.
            t: (3,) cam_from_world translation, metres.
            exclude: indices of sources not to use (leave-one-out evaluation).
            only: if given, use only these sources.
            k: sources per pixel (default ``cfg.ulr.k``).
            fill: fill what the blend leaves empty from the next best photos and the cloud's
                colour (False: those pixels stay black, e.g. for a one-photo baseline).

        Returns:
            The image, proxy depth, per-pixel source count, coverage and fill codes.
        """
        u = self.cfg.ulr
        depth = self.splatter.depth(cam, R, t)
        if cam not in self._rays:
            self._rays[cam] = cam.pixel_rays()
        enabled = self._enabled(exclude, only)
        kk = int(k or u.k)
        on = enabled
        if u.max_sources > 0:
            on = self._preselect(depth, cam, R, t, enabled, kk, u.max_sources)
        surface = np.isfinite(depth)
        d = np.where(surface, depth, 1e30).astype(np.float32)
        out, used = self._blend(cam, R, t, d, on, kk)
        how = np.where(used > 0, FILL_BLEND, FILL_NONE).astype(np.uint8)
        hole = surface & (used == 0)
        if fill and hole.any() and (on != enabled).any():
            # the next best: every other photo that sees these points
            d2 = np.where(hole, d, 1e30).astype(np.float32)
            out2, used2 = self._blend(cam, R, t, d2, enabled, kk)
            got = hole & (used2 > 0)
            out[got], used[got], how[got] = out2[got], used2[got], FILL_NEXT
            hole &= ~got
        if fill and hole.any() and enabled.any():  # no photo sees it: the cloud's colour
            ii, jj = np.nonzero(hole)
            out[ii, jj] = self._hole_colours(cam, R, t, depth, hole, ii, jj)
            how[hole] = FILL_PROXY
        img = np.clip(out + 0.5, 0, 255).astype(np.uint8)
        covered = used > 0
        black = how == FILL_NONE
        if u.inpaint_px > 0 and black.any() and not black.all():
            img = cv2.inpaint(img, black.astype(np.uint8), u.inpaint_px, cv2.INPAINT_TELEA)
        return RenderResult(img, depth, used, float(covered.mean()), how)

    def _blend(self, cam, R, t, d, on, kk):
        """Run the ULR kernel: (H, W, 3) float32 colours and (H, W) int32 source counts."""
        out = np.zeros((cam.height, cam.width, 3), np.float32)
        used = np.zeros((cam.height, cam.width), np.int32)
        pose = np.concatenate([np.asarray(R), np.asarray(t).reshape(3, 1)], 1).astype(np.float32)
        _blend_kernel(kk)(
            d,
            self._rays[cam],
            pose,
            self._pose,
            self._cam,
            on,
            self._img,
            self._vis,
            self._vscale,
            self._kernel_params(),
            out,
            used,
        )
        return out, used
