"""PatchMatch multi-view stereo in taichi (CPU or GPU, same kernels).

Per reference view the solver keeps one plane hypothesis per pixel (z-depth ``d`` and a unit
normal ``n`` in the camera frame, facing the camera) and improves it by

* random initialisation (depth uniform in inverse depth inside the view's depth range),
* red-black (checkerboard) propagation: every pixel tests the planes of 4 or 8 neighbours of
  the other colour (distance 1 and 3), re-evaluated at its own ray,
* refinement: a random hypothesis, a perturbation of the current one whose size halves each
  iteration, and a perturbation of its normal alone at the same depth,
* random draws from a counter-based hash of (pixel, kernel call, draw): a depth map is the same
  however the threads share the pixels,
* a photometric cost: bilaterally weighted NCC over a sparse (2r+1)^2 window (step s) warped by
  the plane-induced homography ``H = K_s (R + t n^T / rho) K_r^-1`` (``rho = n . X``),
* view selection: the cost is the mean of the ``top_k`` best source views, so occluded or
  out-of-view sources do not count,
* coarse-to-fine: a pyramid (2x per level), hypotheses upsampled from the coarser level,
* a geometric-consistency pass (COLMAP style): the cost adds ``geom_weight * min(e, max)`` with
  ``e`` the forward-backward reprojection error through each source's depth map,
* a filter: photometric cost below a threshold and enough geometrically agreeing sources.

Image coordinates follow COLMAP: pixel (row i, column j) has its centre at (j + 0.5, i + 0.5).
"""

import logging
import os
from dataclasses import dataclass

import cv2
import numpy as np

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")
import taichi as ti

from scenebot.dense.config import PatchMatchConfig
from scenebot.taichi_setup import init_taichi, taichi_arch

LOG = logging.getLogger(__name__)

MAX_TOPK = 8
BAD_COST = 2.0  # invalid plane (seen edge-on or from behind): never preferred
OUT_COST = 1.0  # source that does not see the pixel: uninformative, like NCC = 0


@dataclass
class StereoView:
    """A calibrated (undistorted, pinhole) grey image.

    Attributes:
        name: image name in the workspace.
        gray: (H, W) float32 intensities in [0, 1].
        K: (3, 3) pinhole intrinsics, pixels (COLMAP convention, centre of pixel 0 at 0.5).
        R: (3, 3) cam_from_world rotation.
        t: (3,) cam_from_world translation, model units (metres).
    """

    name: str
    gray: np.ndarray
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray


@dataclass
class DepthResult:
    """Output of :meth:`PatchMatchSolver.estimate`.

    Attributes:
        depth: (H, W) float32 z-depth, metres (0 = no depth after filtering).
        normal: (H, W, 3) float32 camera-frame unit normals facing the camera (0 where no depth).
        cost: (H, W) float32 final aggregated cost (photometric 1 - NCC, plus geometric term).
        photo: (H, W) float32 photometric part of the cost (mean 1 - NCC of the selected views).
    """

    depth: np.ndarray
    normal: np.ndarray
    cost: np.ndarray
    photo: np.ndarray


# --------------------------------------------------------------------------------------------
# taichi functions and kernels
# --------------------------------------------------------------------------------------------

nd1 = ti.types.ndarray(dtype=ti.f32, ndim=1)
nd2 = ti.types.ndarray(dtype=ti.f32, ndim=2)
nd3 = ti.types.ndarray(dtype=ti.f32, ndim=3)
nd2i = ti.types.ndarray(dtype=ti.i32, ndim=2)


@ti.func
def _mat3(a: ti.template(), s):
    return ti.Matrix(
        [
            [a[s, 0, 0], a[s, 0, 1], a[s, 0, 2]],
            [a[s, 1, 0], a[s, 1, 1], a[s, 1, 2]],
            [a[s, 2, 0], a[s, 2, 1], a[s, 2, 2]],
        ]
    )


@ti.func
def _vec3(a: ti.template(), s):
    return ti.Vector([a[s, 0], a[s, 1], a[s, 2]])


@ti.func
def _bilinear(img: ti.template(), s, x, y, w, h):
    """Bilinear sample of img[s] at array coordinates (x = column, y = row), clamped."""
    xc = ti.min(ti.max(x, 0.0), w - 1.001)
    yc = ti.min(ti.max(y, 0.0), h - 1.001)
    x0 = ti.cast(ti.floor(xc), ti.i32)
    y0 = ti.cast(ti.floor(yc), ti.i32)
    fx = xc - x0
    fy = yc - y0
    v00 = img[s, y0, x0]
    v01 = img[s, y0, x0 + 1]
    v10 = img[s, y0 + 1, x0]
    v11 = img[s, y0 + 1, x0 + 1]
    return (v00 * (1.0 - fx) + v01 * fx) * (1.0 - fy) + (v10 * (1.0 - fx) + v11 * fx) * fy


@ti.func
def _fb_error(s, x, d, A, b, Q, q, sdepth: ti.template(), src_hw: ti.template()):
    """Forward-backward reprojection error (pixels) and source-depth agreement of X = d K^-1 x.

    Returns (error_px, relative_depth_difference); error = 1e6 when it cannot be evaluated.
    """
    err = 1e6
    rel = 1e6
    xs = d * (A @ x) + b  # K_s (R_s X + t_s)
    if xs.z > 1e-6:
        us = xs.x / xs.z
        vs = xs.y / xs.z
        ws = src_hw[s, 1]
        hs = src_hw[s, 0]
        if us >= 0.0 and vs >= 0.0 and us < ws and vs < hs:
            ds = sdepth[s, ti.cast(vs, ti.i32), ti.cast(us, ti.i32)]
            if ds > 0.0:
                xr = ds * (Q @ ti.Vector([us, vs, 1.0])) + q
                if xr.z > 1e-6:
                    err = ti.sqrt((xr.x / xr.z - x.x) ** 2 + (xr.y / xr.z - x.y) ** 2)
                    rel = ti.abs(ds - xs.z) / ds
    return err, rel


@ti.func
def _ncc_cost(
    i,
    j,
    s,
    Hm,
    uc,
    vc,
    iz,
    wn: ti.template(),
    rn: ti.template(),
    src: ti.template(),
    ws,
    hs,
    R: ti.template(),
    STEP: ti.template(),
):
    """1 - NCC of reference pixel (i, j)'s window against source ``s``, the window warped
    by the homography ``Hm`` expanded to first order at the pixel centre, which it maps to
    (uc, vc) (``iz``: 1 / its homogeneous z); 1 for a textureless source window."""
    NW = ti.static(2 * R // STEP + 1)
    # Jacobian of (u, v) w.r.t. the reference pixel offset (dx, dy)
    jux = (Hm[0, 0] - uc * Hm[2, 0]) * iz
    jvx = (Hm[1, 0] - vc * Hm[2, 0]) * iz
    juy = (Hm[0, 1] - uc * Hm[2, 1]) * iz
    jvy = (Hm[1, 1] - vc * Hm[2, 1]) * iz
    u0 = uc - 0.5
    v0 = vc - 0.5
    s1 = 0.0
    s2 = 0.0
    sx = 0.0
    for ky in ti.static(range(NW)):
        dy = ti.static(ky * STEP - R)
        for kx in ti.static(range(NW)):
            dx = ti.static(kx * STEP - R)
            val = _bilinear(src, s, u0 + dx * jux + dy * juy, v0 + dx * jvx + dy * jvy, ws, hs)
            wk = wn[i, j, ky * NW + kx]
            s1 += wk * val
            s2 += wk * val * val
            sx += rn[i, j, ky * NW + kx] * val
    var = s2 - s1 * s1
    cp = 1.0
    if var > 1e-8:
        cp = 1.0 - ti.min(ti.max(sx / ti.sqrt(var), -1.0), 1.0)
    return cp


@ti.func
def _source_cost(
    i,
    j,
    s,
    x,
    d,
    m,
    wn: ti.template(),
    rn: ti.template(),
    src: ti.template(),
    src_hw: ti.template(),
    A_all: ti.template(),
    b_all: ti.template(),
    Q_all: ti.template(),
    q_all: ti.template(),
    sdepth: ti.template(),
    use_geom,
    geom_w,
    geom_max,
    R: ti.template(),
    STEP: ti.template(),
):
    """Cost of the plane at reference pixel x = (j + 0.5, i + 0.5, 1) (depth ``d``,
    ``m = K_r^-T n / rho``) in source ``s``: (1 - NCC [+ geometric term], 1 - NCC); (larger
    than any valid cost, OUT_COST) where the source does not see the pixel."""
    A = _mat3(A_all, s)
    b = _vec3(b_all, s)
    Hm = A + b.outer_product(m)
    base = Hm @ x
    c = 2.0 * OUT_COST  # larger than any valid cost: an invalid source is never inserted
    cp = OUT_COST
    ws = ti.cast(src_hw[s, 1], ti.f32)
    hs = ti.cast(src_hw[s, 0], ti.f32)
    if base.z > 1e-6:
        iz = 1.0 / base.z
        uc = base.x * iz
        vc = base.y * iz
        if uc >= 0.0 and vc >= 0.0 and uc < ws and vc < hs:
            cp = _ncc_cost(i, j, s, Hm, uc, vc, iz, wn, rn, src, ws, hs, R, STEP)
            c = cp
            if use_geom:
                Q = _mat3(Q_all, s)
                q = _vec3(q_all, s)
                err, _rel = _fb_error(s, x, d, A, b, Q, q, sdepth, src_hw)
                c += geom_w * ti.min(err, geom_max)
    return c, cp


@ti.func
def _insert_top_k(best, best_p, best_i, c, cp, s, top_k):
    """The sorted lists of the ``top_k`` smallest costs (``best``), their photometric parts
    (``best_p``) and sources (``best_i``) with source ``s``'s cost (c, cp) inserted."""
    si = s
    for kk in ti.static(range(MAX_TOPK)):
        if kk < top_k and c < best[kk]:
            tmp = best[kk]
            tmp_p = best_p[kk]
            tmp_i = best_i[kk]
            best[kk] = c
            best_p[kk] = cp
            best_i[kk] = si
            c = tmp
            cp = tmp_p
            si = tmp_i
    return best, best_p, best_i


@ti.func
def _top_k_mean(best, best_p, best_i, top_k):
    """(total, photometric, selected) of :func:`_cost` from its sorted top_k lists."""
    acc = 0.0
    acc_p = 0.0
    n_valid = 0
    selected = 0
    for kk in ti.static(range(MAX_TOPK)):
        if kk < top_k:
            acc += best[kk]
            if best_i[kk] >= 0:
                selected |= 1 << best_i[kk]
                acc_p += best_p[kk]
                n_valid += 1
    total = acc / top_k
    photo = OUT_COST
    if n_valid > 0:
        photo = acc_p / n_valid
    return total, photo, selected


@ti.func
def _cost(
    i,
    j,
    d,
    n,
    kinv,
    wn: ti.template(),
    rn: ti.template(),
    src: ti.template(),
    src_hw: ti.template(),
    A_all: ti.template(),
    b_all: ti.template(),
    Q_all: ti.template(),
    q_all: ti.template(),
    sdepth: ti.template(),
    num_src,
    top_k,
    use_geom,
    geom_w,
    geom_max,
    mask,
    R: ti.template(),
    STEP: ti.template(),
):
    """Aggregated matching cost of plane (d, n) at reference pixel (i, j).

    The window is warped with the first-order (affine) expansion of the plane homography at
    the pixel centre, exact to well below 0.01 px over a few-pixel window.

    Only the sources whose bit is set in ``mask`` are evaluated (mask = -1: all sources).

    Returns:
        (total, photometric, selected): mean over the top_k best sources of (1 - NCC [+
        geometric term]) where a source that does not see the pixel (or costs more than 1)
        counts as 1 (uninformative); the mean 1 - NCC of the selected valid sources (1 if none);
        and the bit mask of those sources.
    """
    x = ti.Vector([j + 0.5, i + 0.5, 1.0])
    ray = kinv @ x
    X = d * ray
    rho = n.dot(X)
    total = BAD_COST
    photo = BAD_COST
    selected = 0
    if rho < -1e-7 and d > 0.0:
        m = (kinv.transpose() @ n) / rho
        # unfilled slots (fewer valid sources than top_k) count as uninformative
        best = ti.Vector([OUT_COST] * MAX_TOPK)
        best_p = ti.Vector([OUT_COST] * MAX_TOPK)
        best_i = ti.Vector([-1] * MAX_TOPK)
        for s in range(num_src):
            if (mask >> s) & 1 == 0:
                continue
            c, cp = _source_cost(
                i, j, s, x, d, m, wn, rn, src, src_hw, A_all, b_all, Q_all, q_all, sdepth,
                use_geom, geom_w, geom_max, R, STEP,
            )  # fmt: skip
            best, best_p, best_i = _insert_top_k(best, best_p, best_i, c, cp, s, top_k)
        total, photo, selected = _top_k_mean(best, best_p, best_i, top_k)
    return total, photo, selected


@ti.func
def _hash32(x: ti.u32) -> ti.u32:
    """An integer hash (lowbias32): the counter-based random numbers below."""
    x ^= x >> ti.u32(16)
    x *= ti.u32(0x7FEB352D)
    x ^= x >> ti.u32(15)
    x *= ti.u32(0x846CA68B)
    x ^= x >> ti.u32(16)
    return x


@ti.func
def _u01(i, j, salt, k):
    """Uniform in [0, 1) from (pixel, call, draw): the same for any thread schedule, so a
    depth map does not depend on how the CPU threads happened to share the pixels."""
    h = _hash32(ti.u32(salt) * ti.u32(0x9E3779B9) + ti.u32(k))
    h = _hash32(h ^ (ti.u32(i) * ti.u32(73856093)) ^ (ti.u32(j) * ti.u32(19349663)))
    return ti.cast(h >> ti.u32(8), ti.f32) * (1.0 / 16777216.0)


@ti.func
def _randn(i, j, salt, k):
    """Standard normal (Box-Muller) from draws ``k`` and ``k + 1``."""
    u1 = ti.max(_u01(i, j, salt, k), 1e-7)
    u2 = _u01(i, j, salt, k + 1)
    return ti.sqrt(-2.0 * ti.log(u1)) * ti.cos(6.283185307 * u2)


@ti.func
def _random_normal(ray, i, j, salt, k):
    """Random unit normal facing the camera (angle to -ray below ~84 degrees)."""
    n = ti.Vector(
        [_randn(i, j, salt, k), _randn(i, j, salt, k + 2), _randn(i, j, salt, k + 4)]
    ).normalized(1e-12)
    rdir = ray.normalized()
    if n.dot(rdir) > 0.0:
        n = -n
    if n.dot(rdir) > -0.1:
        n = (n - 0.5 * rdir).normalized(1e-12)
    return n


@ti.func
def _perturb_normal(n, ray, scale, i, j, salt, k):
    noise = ti.Vector([_randn(i, j, salt, k), _randn(i, j, salt, k + 2), _randn(i, j, salt, k + 4)])
    p = (n + scale * noise).normalized(1e-12)
    if p.dot(ray.normalized()) > -0.05:
        p = n
    return p


@ti.kernel
def _precompute_ref(
    gray: nd2,
    wn: nd3,
    rn: nd3,
    sigma_s: ti.f32,
    sigma_c: ti.f32,
    R: ti.template(),
    STEP: ti.template(),
):
    """Per pixel normalised bilateral weights wn (sum 1) and rn = wn (I - mean) / std."""
    NW = ti.static(2 * R // STEP + 1)
    h, w = gray.shape[0], gray.shape[1]
    for i, j in ti.ndrange(h, w):
        ic = gray[i, j]
        wsum = 0.0
        for ky in ti.static(range(NW)):
            for kx in ti.static(range(NW)):
                dy = ky * STEP - R
                dx = kx * STEP - R
                v = gray[ti.min(ti.max(i + dy, 0), h - 1), ti.min(ti.max(j + dx, 0), w - 1)]
                wk = ti.exp(
                    -(dx * dx + dy * dy) / (2.0 * sigma_s * sigma_s)
                    - (v - ic) ** 2 / (2.0 * sigma_c * sigma_c)
                )
                wn[i, j, ky * NW + kx] = wk
                rn[i, j, ky * NW + kx] = v
                wsum += wk
        mean = 0.0
        for k in ti.static(range(NW * NW)):
            wn[i, j, k] /= wsum
            mean += wn[i, j, k] * rn[i, j, k]
        var = 0.0
        for k in ti.static(range(NW * NW)):
            var += wn[i, j, k] * (rn[i, j, k] - mean) ** 2
        inv_std = 0.0
        if var > 1e-6:  # textureless windows get rn = 0, i.e. NCC 0 (cost 1)
            inv_std = 1.0 / ti.sqrt(var)
        for k in ti.static(range(NW * NW)):
            rn[i, j, k] = wn[i, j, k] * (rn[i, j, k] - mean) * inv_std


@ti.kernel
def _random_init(depth: nd2, normal: nd3, kinv_a: nd2, dmin: ti.f32, dmax: ti.f32, salt: ti.i32):
    kinv = ti.Matrix([[kinv_a[r, c] for c in ti.static(range(3))] for r in ti.static(range(3))])
    for i, j in depth:
        ray = kinv @ ti.Vector([j + 0.5, i + 0.5, 1.0])
        inv = 1.0 / dmax + _u01(i, j, salt, 0) * (1.0 / dmin - 1.0 / dmax)
        depth[i, j] = 1.0 / inv
        n = _random_normal(ray, i, j, salt, 1)
        for c in ti.static(range(3)):
            normal[i, j, c] = n[c]


@ti.kernel
def _eval_all(
    depth: nd2,
    normal: nd3,
    cost: nd2,
    photo: nd2,
    sel: nd2i,
    kinv_a: nd2,
    wn: nd3,
    rn: nd3,
    src: nd3,
    src_hw: nd2i,
    A_all: nd3,
    b_all: nd2,
    Q_all: nd3,
    q_all: nd2,
    sdepth: nd3,
    num_src: ti.i32,
    top_k: ti.i32,
    use_geom: ti.i32,
    geom_w: ti.f32,
    geom_max: ti.f32,
    R: ti.template(),
    STEP: ti.template(),
):
    kinv = ti.Matrix([[kinv_a[r, c] for c in ti.static(range(3))] for r in ti.static(range(3))])
    for i, j in depth:
        n = ti.Vector([normal[i, j, 0], normal[i, j, 1], normal[i, j, 2]])
        c, cp, m = _cost(
            i, j, depth[i, j], n, kinv, wn, rn, src, src_hw, A_all, b_all, Q_all, q_all,
            sdepth, num_src, top_k, use_geom, geom_w, geom_max, -1, R, STEP,
        )  # fmt: skip
        cost[i, j] = c
        photo[i, j] = cp
        sel[i, j] = m


@ti.func
def _neighbour_plane(i, j, k, ray, bn, kinv, depth: ti.template(), normal: ti.template()):
    """Propagation candidate ``k``: the plane of neighbour k ((0,1),(0,-1),(1,0),(-1,0) at
    distance 1, then 3) re-evaluated at this pixel's ``ray``, as (depth, normal); depth -1
    (and normal ``bn``) where the neighbour lies outside the image or its plane is seen
    edge-on or from behind along the ray."""
    h, w = depth.shape[0], depth.shape[1]
    cd = -1.0
    cn = bn
    dist = 1 + 2 * (k // 4)
    sgn = 1 - 2 * (k % 2)
    di = 0
    dj = 0
    if (k // 2) % 2 == 0:
        dj = sgn * dist
    else:
        di = sgn * dist
    i2 = i + di
    j2 = j + dj
    if i2 >= 0 and i2 < h and j2 >= 0 and j2 < w:
        n2 = ti.Vector([normal[i2, j2, 0], normal[i2, j2, 1], normal[i2, j2, 2]])
        X2 = depth[i2, j2] * (kinv @ ti.Vector([j2 + 0.5, i2 + 0.5, 1.0]))
        den = n2.dot(ray)
        if den < -1e-7:
            cd = n2.dot(X2) / den
            cn = n2
    return cd, cn


@ti.func
def _random_plane(i, j, ray, inv_lo, inv_hi, salt):
    """A random candidate plane: depth uniform in inverse depth, a random normal facing the
    camera; (depth, normal)."""
    cd = 1.0 / (inv_lo + _u01(i, j, salt, 0) * (inv_hi - inv_lo))
    cn = _random_normal(ray, i, j, salt, 1)
    return cd, cn


@ti.func
def _perturbed_plane(i, j, ray, bd, bn, scale, inv_lo, inv_hi, salt):
    """The best plane (bd, bn) so far perturbed: its inverse depth by up to ``scale`` of the
    inverse-depth span, its normal by noise of size ``scale``; (depth, normal), depth -1
    (and normal ``bn``) where the depth leaves the range."""
    cd = -1.0
    cn = bn
    inv_p = 1.0 / bd + (2.0 * _u01(i, j, salt, 7) - 1.0) * (inv_hi - inv_lo) * scale
    if inv_p > inv_lo and inv_p < inv_hi:
        cd = 1.0 / inv_p
        cn = _perturb_normal(bn, ray, scale, i, j, salt, 8)
    return cd, cn


@ti.kernel
def _sweep(
    color: ti.i32,
    scale: ti.f32,
    do_random: ti.i32,
    num_nb: ti.i32,
    use_sel: ti.i32,
    depth: nd2,
    normal: nd3,
    cost: nd2,
    photo: nd2,
    sel: nd2i,
    kinv_a: nd2,
    wn: nd3,
    rn: nd3,
    src: nd3,
    src_hw: nd2i,
    A_all: nd3,
    b_all: nd2,
    Q_all: nd3,
    q_all: nd2,
    sdepth: nd3,
    num_src: ti.i32,
    top_k: ti.i32,
    use_geom: ti.i32,
    geom_w: ti.f32,
    geom_max: ti.f32,
    dmin: ti.f32,
    dmax: ti.f32,
    R: ti.template(),
    STEP: ti.template(),
    salt: ti.i32,
):
    """One half (red or black) of a PatchMatch iteration: propagation then refinement.

    Candidates per pixel: the planes of ``num_nb`` (4 or 8) neighbours of the other colour
    (distance 1, then 3), a random hypothesis when ``do_random``, a perturbation of the best
    one (inverse-depth span and normal noise proportional to ``scale``) and a perturbation of
    its normal alone. With ``use_sel`` only the pixel's selected sources (``sel``, from
    :func:`_eval_all`) are evaluated.
    """
    kinv = ti.Matrix([[kinv_a[r, c] for c in ti.static(range(3))] for r in ti.static(range(3))])
    h, w = depth.shape[0], depth.shape[1]
    half_w = (w + 1) // 2
    inv_lo = 1.0 / dmax
    inv_hi = 1.0 / dmin
    for i, jj in ti.ndrange(h, half_w):
        j = 2 * jj + (i + color) % 2
        if j < w:
            x = ti.Vector([j + 0.5, i + 0.5, 1.0])
            ray = kinv @ x
            bd = depth[i, j]
            bn = ti.Vector([normal[i, j, 0], normal[i, j, 1], normal[i, j, 2]])
            bc = cost[i, j]
            bp = photo[i, j]
            mask = -1
            if use_sel:
                mask = sel[i, j]
            n_cand = num_nb + 3
            for k in range(n_cand):
                cd = -1.0
                cn = bn
                if k < num_nb:
                    cd, cn = _neighbour_plane(i, j, k, ray, bn, kinv, depth, normal)
                elif k == num_nb:
                    if do_random:
                        cd, cn = _random_plane(i, j, ray, inv_lo, inv_hi, salt)
                elif k == num_nb + 2:
                    # the normal alone: once the depth is right, a joint perturbation rarely
                    # improves the normal because the depth step costs more than the tilt gains
                    cd = bd
                    cn = _perturb_normal(bn, ray, scale, i, j, salt, 14)
                else:
                    cd, cn = _perturbed_plane(i, j, ray, bd, bn, scale, inv_lo, inv_hi, salt)
                if cd >= dmin and cd <= dmax:
                    c2, p2, _m = _cost(
                        i, j, cd, cn, kinv, wn, rn, src, src_hw, A_all, b_all, Q_all, q_all,
                        sdepth, num_src, top_k, use_geom, geom_w, geom_max, mask, R, STEP,
                    )  # fmt: skip
                    if c2 < bc:
                        bc = c2
                        bp = p2
                        bd = cd
                        bn = cn
            depth[i, j] = bd
            cost[i, j] = bc
            photo[i, j] = bp
            for c in ti.static(range(3)):
                normal[i, j, c] = bn[c]


@ti.kernel
def _consistency(
    depth: nd2,
    count: nd2,
    kinv_a: nd2,
    src_hw: nd2i,
    A_all: nd3,
    b_all: nd2,
    Q_all: nd3,
    q_all: nd2,
    sdepth: nd3,
    num_src: ti.i32,
    max_err: ti.f32,
    max_rel: ti.f32,
):
    """Number of sources whose depth map agrees with each reference pixel."""
    kinv = ti.Matrix([[kinv_a[r, c] for c in ti.static(range(3))] for r in ti.static(range(3))])
    for i, j in depth:
        d = depth[i, j]
        n_ok = 0
        if d > 0.0:
            x = ti.Vector([j + 0.5, i + 0.5, 1.0])
            for s in range(num_src):
                A = _mat3(A_all, s)
                b = _vec3(b_all, s)
                Q = _mat3(Q_all, s)
                q = _vec3(q_all, s)
                err, rel = _fb_error(s, x, d, A, b, Q, q, sdepth, src_hw)
                if err < max_err and rel < max_rel:
                    n_ok += 1
        _ = kinv
        count[i, j] = ti.cast(n_ok, ti.f32)


# --------------------------------------------------------------------------------------------
# host side
# --------------------------------------------------------------------------------------------


def scale_intrinsics(K: np.ndarray, sx: float, sy: float) -> np.ndarray:
    """Intrinsics of an image resized by (sx, sy) (COLMAP pixel-corner convention)."""
    Ks = np.asarray(K, dtype=np.float64).copy()
    Ks[0] *= sx
    Ks[1] *= sy
    return Ks


def _pyramid(gray: np.ndarray, levels: int) -> list[np.ndarray]:
    out = [gray.astype(np.float32)]
    for _ in range(1, levels):
        g = out[-1]
        h, w = g.shape[0] // 2, g.shape[1] // 2
        out.append(cv2.resize(g[: 2 * h, : 2 * w], (w, h), interpolation=cv2.INTER_AREA))
    return out


def _on_cpu() -> bool:
    """Whether taichi runs on the CPU: its kernels then take numpy arrays in place (no copy);
    on a GPU the arrays live on the device (``ti.ndarray``) across the kernel calls."""
    return taichi_arch() in ("x64", "arm64")


def _ndarray(a: np.ndarray, dtype=ti.f32):
    """``a`` as a kernel argument: a contiguous numpy array on the CPU, a device array on a
    GPU."""
    a = np.ascontiguousarray(a, dtype=np.float32 if dtype == ti.f32 else np.int32)
    if _on_cpu():
        return a
    arr = ti.ndarray(dtype=dtype, shape=a.shape)
    arr.from_numpy(a)
    return arr


def _empty(shape: tuple, dtype=ti.f32):
    """An uninitialised kernel argument of ``shape`` (see :func:`_ndarray`)."""
    if _on_cpu():
        return np.empty(shape, np.float32 if dtype == ti.f32 else np.int32)
    return ti.ndarray(dtype, shape)


def _to_numpy(a) -> np.ndarray:
    """A kernel argument's values as a numpy array (the array itself on the CPU)."""
    return a if isinstance(a, np.ndarray) else a.to_numpy()


def _fill_from(a, values: np.ndarray) -> None:
    """Copy ``values`` into the kernel argument ``a`` (of the same shape)."""
    if isinstance(a, np.ndarray):
        a[...] = values
    else:
        a.from_numpy(np.ascontiguousarray(values, dtype=np.float32))


class PatchMatchSolver:
    """Taichi PatchMatch stereo for one reference view at a time.

    Args:
        cfg: PatchMatch settings.
    """

    def __init__(self, cfg: PatchMatchConfig | None = None):
        self.cfg = cfg or PatchMatchConfig()
        if taichi_arch() is None:
            init_taichi("auto", -1, self.cfg.seed)
        r, step = self.cfg.window_radius, self.cfg.window_step
        if (2 * r) % step:
            raise ValueError(
                f"patchmatch: 2 * window_radius ({2 * r}) must be a multiple of window_step "
                f"({step}) so that the window is symmetric"
            )
        self.nw = 2 * r // step + 1

    def _next_salt(self) -> int:
        """A new stream of random draws for the next kernel call (see :func:`_u01`)."""
        self._salt = getattr(self, "_salt", 0) + 1
        return self._salt

    # -- geometry of one level ---------------------------------------------------------------
    @staticmethod
    def _relative(ref: StereoView, srcs: list[StereoView], Kr: np.ndarray, Ks: list[np.ndarray]):
        """Per-source A = K_s R K_r^-1, b = K_s t, Q = K_r R^T K_s^-1, q = -K_r R^T t."""
        S = len(srcs)
        A = np.zeros((S, 3, 3), np.float32)
        b = np.zeros((S, 3), np.float32)
        Q = np.zeros((S, 3, 3), np.float32)
        q = np.zeros((S, 3), np.float32)
        Kr_inv = np.linalg.inv(Kr)
        for s, (v, K) in enumerate(zip(srcs, Ks, strict=True)):
            R = v.R @ ref.R.T
            t = v.t - R @ ref.t
            A[s] = K @ R @ Kr_inv
            b[s] = K @ t
            Q[s] = Kr @ R.T @ np.linalg.inv(K)
            q[s] = -Kr @ R.T @ t
        return A, b, Q, q

    @staticmethod
    def _stack(arrays: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        hs = max(a.shape[0] for a in arrays)
        ws = max(a.shape[1] for a in arrays)
        out = np.zeros((len(arrays), hs, ws), np.float32)
        hw = np.zeros((len(arrays), 2), np.int32)
        for s, a in enumerate(arrays):
            out[s, : a.shape[0], : a.shape[1]] = a
            hw[s] = a.shape[:2]
        return out, hw

    def _level_data(
        self,
        ref_gray: np.ndarray,
        src_grays: list[np.ndarray],
        Kr: np.ndarray,
        Ks: list[np.ndarray],
        ref: StereoView,
        srcs: list[StereoView],
        src_depths: list[np.ndarray] | None,
    ) -> dict:
        cfg = self.cfg
        h, w = ref_gray.shape
        src, hw = self._stack(src_grays)
        sd = np.zeros_like(src)
        if src_depths is not None:
            for s, dm in enumerate(src_depths):
                if dm.shape != src_grays[s].shape:
                    raise ValueError(
                        f"depth map of source {srcs[s].name} has shape {dm.shape}, expected "
                        f"{src_grays[s].shape}"
                    )
                sd[s, : dm.shape[0], : dm.shape[1]] = dm
        A, b, Q, q = self._relative(ref, srcs, Kr, Ks)
        wn = _empty((h, w, self.nw * self.nw))
        rn = _empty((h, w, self.nw * self.nw))
        sig_s = cfg.sigma_spatial if cfg.sigma_spatial > 0 else float(cfg.window_radius)
        _precompute_ref(
            _ndarray(ref_gray), wn, rn, sig_s, cfg.sigma_color, cfg.window_radius, cfg.window_step
        )
        return {
            "kinv": _ndarray(np.linalg.inv(Kr)),
            "wn": wn,
            "rn": rn,
            "src": _ndarray(src),
            "src_hw": _ndarray(hw, ti.i32),
            "A": _ndarray(A),
            "b": _ndarray(b),
            "Q": _ndarray(Q),
            "q": _ndarray(q),
            "sdepth": _ndarray(sd),
            "num_src": len(srcs),
        }

    def _cost_args(self, L: dict, use_geom: bool) -> tuple:
        cfg = self.cfg
        return (
            L["kinv"], L["wn"], L["rn"], L["src"], L["src_hw"], L["A"], L["b"], L["Q"], L["q"],
            L["sdepth"], L["num_src"], min(cfg.top_k, L["num_src"], MAX_TOPK), int(use_geom),
            cfg.geom_weight, cfg.geom_max_error,
        )  # fmt: skip

    def _iterate(
        self,
        L: dict,
        maps: tuple,
        iterations: int,
        use_geom: bool,
        depth_range: tuple[float, float],
        scale0: float,
        random_restarts: bool,
        num_nb: int,
        use_sel: bool,
    ) -> None:
        cfg = self.cfg
        depth, normal, cost, photo, sel = maps
        args = self._cost_args(L, use_geom)
        _eval_all(depth, normal, cost, photo, sel, *args, cfg.window_radius, cfg.window_step)
        scale = scale0
        for _ in range(iterations):
            for color in (0, 1):
                _sweep(
                    color, scale, int(random_restarts), num_nb, int(use_sel), depth, normal,
                    cost, photo, sel, *args, depth_range[0], depth_range[1], cfg.window_radius,
                    cfg.window_step, self._next_salt(),
                )  # fmt: skip
            scale *= 0.5

    # -- public API ---------------------------------------------------------------------------
    def estimate(
        self,
        ref: StereoView,
        srcs: list[StereoView],
        depth_range: tuple[float, float],
        src_depths: list[np.ndarray] | None = None,
        init: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> DepthResult:
        """Estimate a depth and normal map for ``ref``.

        Without ``src_depths`` this is the photometric pass (coarse-to-fine from a random
        initialisation). With ``src_depths`` (one (H_s, W_s) depth map per source, 0 = none)
        and ``init`` (the photometric depth (H, W) and normal (H, W, 3)), it runs the
        geometric-consistency iterations at full resolution.

        Args:
            ref: reference view.
            srcs: source views (1 to 8).
            depth_range: (min, max) z-depth searched, metres.
            src_depths: full-resolution depth maps of the sources for the geometric pass.
            init: starting hypotheses for the geometric pass.

        Returns:
            Unfiltered depth, normal, cost and photometric cost maps at full resolution.
        """
        self._salt = self.cfg.seed * 7919  # the random draws restart: repeatable per view
        cfg = self.cfg
        if not srcs:
            raise ValueError(f"view {ref.name}: no source views, cannot estimate depth")
        if len(srcs) > MAX_TOPK:
            raise ValueError(f"view {ref.name}: {len(srcs)} source views, at most {MAX_TOPK}")
        dmin, dmax = float(depth_range[0]), float(depth_range[1])
        if not (0 < dmin < dmax):
            raise ValueError(f"view {ref.name}: invalid depth range {depth_range}")
        geometric = src_depths is not None
        if geometric and init is None:
            raise ValueError("the geometric pass needs init=(depth, normal) from the photometric")
        levels = 1 if geometric else len(cfg.iterations)
        ref_pyr = _pyramid(ref.gray, levels)
        src_pyr = [_pyramid(v.gray, levels) for v in srcs]
        depth_np = normal_np = cost_np = photo_np = None
        for lev in range(levels - 1, -1, -1):
            g = ref_pyr[lev]
            h, w = g.shape
            Kr = scale_intrinsics(ref.K, w / ref.gray.shape[1], h / ref.gray.shape[0])
            Ks = []
            for v, pyr in zip(srcs, src_pyr, strict=True):
                gs = pyr[lev]
                sx, sy = gs.shape[1] / v.gray.shape[1], gs.shape[0] / v.gray.shape[0]
                Ks.append(scale_intrinsics(v.K, sx, sy))
            L = self._level_data(
                g, [p[lev] for p in src_pyr], Kr, Ks, ref, srcs, src_depths if geometric else None
            )
            maps = (
                _empty((h, w)),
                _empty((h, w, 3)),
                _empty((h, w)),
                _empty((h, w)),
                _empty((h, w), ti.i32),
            )
            if geometric:
                _fill_from(maps[0], init[0])
                _fill_from(maps[1], init[1])
                iters, nb = cfg.geom_iterations, cfg.neighbors[0]
            else:
                iters, nb = cfg.iterations[lev], cfg.neighbors[min(lev, len(cfg.neighbors) - 1)]
                if depth_np is None:
                    _random_init(maps[0], maps[1], L["kinv"], dmin, dmax, self._next_salt())
                else:
                    up_d = cv2.resize(depth_np, (w, h), interpolation=cv2.INTER_NEAREST)
                    up_n = cv2.resize(normal_np, (w, h), interpolation=cv2.INTER_NEAREST)
                    _fill_from(maps[0], up_d)
                    _fill_from(maps[1], up_n)
            # perturbation size: large on the coarsest level, small once upsampled
            scale0 = 0.25 * 0.4 ** (levels - 1 - lev) if not geometric else 0.01
            rnd = (not geometric) and lev > 0
            use_sel = geometric or (lev < cfg.view_selection_levels and cfg.fine_view_selection)
            self._iterate(L, maps, iters, geometric, (dmin, dmax), scale0, rnd, nb, use_sel)
            depth_np, normal_np, cost_np, photo_np = (_to_numpy(m) for m in maps[:4])
        return DepthResult(depth_np, normal_np, cost_np, photo_np)

    def consistent_count(
        self, ref: StereoView, srcs: list[StereoView], depth: np.ndarray, src_depths: list
    ) -> np.ndarray:
        """Per pixel, the number of sources whose depth map agrees (forward-backward error and
        relative depth thresholds of the config). Returns (H, W) float32."""
        cfg = self.cfg
        for v, dm in zip(srcs, src_depths, strict=True):
            if dm.shape != v.gray.shape:
                raise ValueError(f"depth map of {v.name} has shape {dm.shape}, not {v.gray.shape}")
        sd, hw = self._stack(list(src_depths))
        A, b, Q, q = self._relative(ref, srcs, ref.K, [v.K for v in srcs])
        count = _empty(depth.shape)
        _consistency(
            _ndarray(depth), count, _ndarray(np.linalg.inv(ref.K)), _ndarray(hw, ti.i32),
            _ndarray(A), _ndarray(b), _ndarray(Q), _ndarray(q), _ndarray(sd), len(srcs),
            cfg.filter_max_reproj_error, cfg.filter_max_rel_depth_error,
        )  # fmt: skip
        return _to_numpy(count)

    def filter(
        self,
        ref: StereoView,
        srcs: list[StereoView],
        result: DepthResult,
        src_depths: list[np.ndarray] | None,
    ) -> DepthResult:
        """Zero the depth of unreliable pixels.

        A pixel is kept when its photometric cost (mean 1 - NCC of its selected sources) is
        below ``filter_max_cost`` and, if source depth maps are given, at least
        ``filter_min_consistent`` sources agree with it.
        """
        cfg = self.cfg
        keep = (result.photo < cfg.filter_max_cost) & (result.depth > 0)
        if src_depths is not None and cfg.filter_min_consistent > 0:
            cnt = self.consistent_count(ref, srcs, result.depth, src_depths)
            keep &= cnt >= cfg.filter_min_consistent
        depth = np.where(keep, result.depth, 0.0).astype(np.float32)
        normal = np.where(keep[..., None], result.normal, 0.0).astype(np.float32)
        return DepthResult(depth, normal, result.cost, result.photo)
