"""Taichi kernels of the score (see :mod:`scenebot.score.kernel` for the definition).

This module must not use ``from __future__ import annotations``: taichi reads the kernel
argument annotations as objects. Kernels are defined at import and compiled at first call,
after :func:`scenebot.score.kernel.init_taichi`.
"""

import taichi as ti

FAR = 1.0e30
RASTER_CHUNK = 64  # triangles per parallel task of the rasterizer
nd = ti.types.ndarray


nd = ti.types.ndarray


@ti.kernel
def fill(a: nd(dtype=ti.f32, ndim=3), value: ti.f32):
    for b, j, i in ti.ndrange(a.shape[0], a.shape[1], a.shape[2]):
        a[b, j, i] = value


@ti.func
def view_rt(views: ti.template(), b: ti.i32):
    R = ti.Matrix(
        [
            [views[b, 0], views[b, 1], views[b, 2]],
            [views[b, 3], views[b, 4], views[b, 5]],
            [views[b, 6], views[b, 7], views[b, 8]],
        ]
    )
    t = ti.Vector([views[b, 9], views[b, 10], views[b, 11]])
    return R, t


@ti.kernel
def raster(
    verts: nd(dtype=ti.f32, ndim=2),
    tris: nd(dtype=ti.i32, ndim=2),
    spheres: nd(dtype=ti.f32, ndim=2),
    views: nd(dtype=ti.f32, ndim=2),
    depth: nd(dtype=ti.f32, ndim=3),
    near: ti.f32,
):
    """Z-buffer (min of z-depth, m) of every view; ``depth`` must start at FAR.

    One parallel task per (view, chunk of RASTER_CHUNK triangles), atomic depth writes: for
    GPUs, which need many more threads than there are views.
    """
    T = tris.shape[0]
    for b, chunk in ti.ndrange(depth.shape[0], (T + RASTER_CHUNK - 1) // RASTER_CHUNK):
        raster_range(
            verts,
            tris,
            spheres,
            views,
            depth,
            near,
            b,
            chunk * RASTER_CHUNK,
            ti.min(T, (chunk + 1) * RASTER_CHUNK),
            True,
        )


@ti.kernel
def raster_per_view(
    verts: nd(dtype=ti.f32, ndim=2),
    tris: nd(dtype=ti.i32, ndim=2),
    spheres: nd(dtype=ti.f32, ndim=2),
    views: nd(dtype=ti.f32, ndim=2),
    depth: nd(dtype=ti.f32, ndim=3),
    near: ti.f32,
):
    """As :func:`raster`, one parallel task per view and plain depth writes: for CPUs."""
    for b in range(depth.shape[0]):
        raster_range(verts, tris, spheres, views, depth, near, b, 0, tris.shape[0], False)


@ti.func
def raster_range(
    verts: ti.template(),
    tris: ti.template(),
    spheres: ti.template(),
    views: ti.template(),
    depth: ti.template(),
    near: ti.f32,
    b: ti.i32,
    k0: ti.i32,
    k1: ti.i32,
    atomic: ti.template(),
):
    """Rasterize triangles k0..k1-1 into view b, skipping those whose bounding sphere
    (``spheres`` (T, 4): centroid and radius, m) lies outside the view frustum."""
    H = depth.shape[1]
    W = depth.shape[2]
    R, t = view_rt(views, b)
    fx, fy, cx, cy = views[b, 15], views[b, 16], views[b, 17], views[b, 18]
    # unit normals of the four side planes of the frustum (camera frame, inside >= 0)
    nl = ti.Vector([fx, cx]).normalized()
    nr = ti.Vector([-fx, W - cx]).normalized()
    nt = ti.Vector([fy, cy]).normalized()
    nb = ti.Vector([-fy, H - cy]).normalized()
    for k in range(k0, k1):
        sc = R @ ti.Vector([spheres[k, 0], spheres[k, 1], spheres[k, 2]]) + t
        rad = spheres[k, 3]
        cut = sc.z < near - rad
        cut |= nl[0] * sc.x + nl[1] * sc.z < -rad
        cut |= nr[0] * sc.x + nr[1] * sc.z < -rad
        cut |= nt[0] * sc.y + nt[1] * sc.z < -rad
        cut |= nb[0] * sc.y + nb[1] * sc.z < -rad
        if not cut:
            i0, i1, i2 = tris[k, 0], tris[k, 1], tris[k, 2]
            a = R @ ti.Vector([verts[i0, 0], verts[i0, 1], verts[i0, 2]]) + t
            bb = R @ ti.Vector([verts[i1, 0], verts[i1, 1], verts[i1, 2]]) + t
            c = R @ ti.Vector([verts[i2, 0], verts[i2, 1], verts[i2, 2]]) + t
            raster_triangle(a, bb, c, b, fx, fy, cx, cy, depth, near, atomic)


@ti.func
def raster_triangle(
    a: ti.template(),
    bb: ti.template(),
    c: ti.template(),
    b: ti.i32,
    fx: ti.f32,
    fy: ti.f32,
    cx: ti.f32,
    cy: ti.f32,
    depth: ti.template(),
    near: ti.f32,
    atomic: ti.template(),
):
    """Write one camera-frame triangle into the z-buffer of view ``b`` (with atomic writes
    when other threads may write the same view).

    A triangle wholly beyond the near plane is rasterized with screen-space edge functions
    (pixel centres inside or on an edge; depth from the perspective-correct interpolation of
    1/z); one that crosses the near plane is clipped by ray casting every pixel of its clipped
    screen bounding box (Moller-Trumbore).
    """
    H = depth.shape[1]
    W = depth.shape[2]
    if ti.min(a.z, bb.z, c.z) > near:
        u0, v0 = fx * a.x / a.z + cx, fy * a.y / a.z + cy
        u1, v1 = fx * bb.x / bb.z + cx, fy * bb.y / bb.z + cy
        u2, v2 = fx * c.x / c.z + cx, fy * c.y / c.z + cy
        area = (u1 - u0) * (v2 - v0) - (u2 - u0) * (v1 - v0)
        if ti.abs(area) > 1e-12:
            inv_area = 1.0 / area
            ja = ti.max(0, ti.cast(ti.ceil(ti.min(v0, v1, v2) - 0.5), ti.i32))
            jb = ti.min(H - 1, ti.cast(ti.floor(ti.max(v0, v1, v2) - 0.5), ti.i32))
            ia = ti.max(0, ti.cast(ti.ceil(ti.min(u0, u1, u2) - 0.5), ti.i32))
            ib = ti.min(W - 1, ti.cast(ti.floor(ti.max(u0, u1, u2) - 0.5), ti.i32))
            iz0, iz1, iz2 = 1.0 / a.z, 1.0 / bb.z, 1.0 / c.z
            eps = -1e-5
            for j in range(ja, jb + 1):
                pv = j + 0.5
                for i in range(ia, ib + 1):
                    pu = i + 0.5
                    # barycentric weights of the pixel centre
                    w0 = ((u1 - pu) * (v2 - pv) - (u2 - pu) * (v1 - pv)) * inv_area
                    w1 = ((u2 - pu) * (v0 - pv) - (u0 - pu) * (v2 - pv)) * inv_area
                    w2 = 1.0 - w0 - w1
                    if w0 >= eps and w1 >= eps and w2 >= eps:
                        z = 1.0 / (w0 * iz0 + w1 * iz1 + w2 * iz2)
                        if ti.static(atomic):
                            ti.atomic_min(depth[b, j, i], z)
                        else:
                            depth[b, j, i] = ti.min(depth[b, j, i], z)
    elif ti.max(a.z, bb.z, c.z) > near:
        umin, umax, vmin, vmax = FAR, -FAR, FAR, -FAR
        # screen bounds of the triangle clipped at z = near: projected front vertices
        # and the points where edges cross the near plane
        for e in ti.static(range(3)):
            p = a
            q = bb
            if ti.static(e == 1):
                p = bb
                q = c
            if ti.static(e == 2):
                p = c
                q = a
            if p.z >= near:
                umin = ti.min(umin, fx * p.x / p.z + cx)
                umax = ti.max(umax, fx * p.x / p.z + cx)
                vmin = ti.min(vmin, fy * p.y / p.z + cy)
                vmax = ti.max(vmax, fy * p.y / p.z + cy)
            if (p.z - near) * (q.z - near) < 0:
                s = (near - p.z) / (q.z - p.z)
                x = p + s * (q - p)
                umin = ti.min(umin, fx * x.x / near + cx)
                umax = ti.max(umax, fx * x.x / near + cx)
                vmin = ti.min(vmin, fy * x.y / near + cy)
                vmax = ti.max(vmax, fy * x.y / near + cy)
        ja = ti.max(0, ti.cast(ti.ceil(ti.max(vmin, -1.0) - 0.5), ti.i32))
        jb = ti.min(H - 1, ti.cast(ti.floor(ti.min(vmax, H + 1.0) - 0.5), ti.i32))
        ia = ti.max(0, ti.cast(ti.ceil(ti.max(umin, -1.0) - 0.5), ti.i32))
        ib = ti.min(W - 1, ti.cast(ti.floor(ti.min(umax, W + 1.0) - 0.5), ti.i32))
        e1 = bb - a
        e2 = c - a
        tv = -a
        qv = tv.cross(e1)
        tq = e2.dot(qv)
        for j in range(ja, jb + 1):
            dy = (j + 0.5 - cy) / fy
            for i in range(ia, ib + 1):
                d = ti.Vector([(i + 0.5 - cx) / fx, dy, 1.0])
                pv = d.cross(e2)
                det = e1.dot(pv)
                if ti.abs(det) > 1e-12:
                    inv = 1.0 / det
                    u = tv.dot(pv) * inv
                    v = d.dot(qv) * inv
                    z = tq * inv
                    if u >= -1e-6 and v >= -1e-6 and u + v <= 1.0 + 1e-6 and z > near:
                        if ti.static(atomic):
                            ti.atomic_min(depth[b, j, i], z)
                        else:
                            depth[b, j, i] = ti.min(depth[b, j, i], z)


@ti.func
def pixel_point(views: ti.template(), b: ti.i32, j: ti.i32, i: ti.i32, z: ti.f32):
    """World point (m) of pixel (j, i) of view b at z-depth z."""
    R, t = view_rt(views, b)
    fx, fy, cx, cy = views[b, 15], views[b, 16], views[b, 17], views[b, 18]
    pc = ti.Vector([(i + 0.5 - cx) / fx * z, (j + 0.5 - cy) / fy * z, z])
    return R.transpose() @ (pc - t)


@ti.kernel
def tile_bounds(
    depth: nd(dtype=ti.f32, ndim=3),
    views: nd(dtype=ti.f32, ndim=2),
    tiles_x: ti.i32,
    tiles_y: ti.i32,
    bounds: nd(dtype=ti.f32, ndim=3),
):
    """Per tile of each view: bounds (B, tiles, 9) of its hit points (m): min xyz, max xyz,
    mean xyz.

    Tile (kx, ky) holds the pixels with ``(i * tiles_x) // W == kx`` and
    ``(j * tiles_y) // H == ky``; its index is ``kx + tiles_x * ky``.
    """
    H = depth.shape[1]
    W = depth.shape[2]
    for b, k in ti.ndrange(bounds.shape[0], bounds.shape[1]):
        kx = k % tiles_x
        ky = k // tiles_x
        lo = ti.Vector([FAR, FAR, FAR])
        hi = ti.Vector([-FAR, -FAR, -FAR])
        acc = ti.Vector([0.0, 0.0, 0.0])
        n = 0
        for j in range((ky * H + tiles_y - 1) // tiles_y, ((ky + 1) * H + tiles_y - 1) // tiles_y):
            for i in range(
                (kx * W + tiles_x - 1) // tiles_x, ((kx + 1) * W + tiles_x - 1) // tiles_x
            ):
                z = depth[b, j, i]
                if z < FAR:
                    P = pixel_point(views, b, j, i, z)
                    lo = ti.min(lo, P)
                    hi = ti.max(hi, P)
                    acc += P
                    n += 1
        acc /= ti.max(n, 1)
        for c in ti.static(range(3)):
            bounds[b, k, c] = lo[c]
            bounds[b, k, c + 3] = hi[c]
            bounds[b, k, c + 6] = acc[c]


@ti.kernel
def cull(
    bounds: nd(dtype=ti.f32, ndim=3),
    views: nd(dtype=ti.f32, ndim=2),
    src_centres: nd(dtype=ti.math.vec3, ndim=1),
    planes: nd(dtype=ti.f32, ndim=3),
    lists: nd(dtype=ti.i32, ndim=3),
    keys: nd(dtype=ti.f32, ndim=3),
    n_active: nd(dtype=ti.i32, ndim=2),
):
    """Per (candidate, tile): the sources whose frustum may hold one of the tile's points.

    ``planes`` (S, 5, 4) are the world-frame planes n.x + d >= 0 bounding each source's
    frustum; a source is dropped when the tile's bounding box lies wholly outside one of them.
    The kept sources are sorted by a lower bound of their angle over all of the tile's points,
    and ``keys`` receives the cosine of that bound, so that the per-pixel search can stop as
    soon as no later source can beat its best angle: for the tile's mean point Pm and radius
    rho (largest distance from Pm to the bounding box), the direction from a point P of the
    tile towards X differs from that of Pm by at most asin(rho / |X - Pm|) (pi when
    rho >= |X - Pm|), hence theta_i(P) >= theta_i(Pm) - delta(L) - delta(L_i).
    """
    for b, k in ti.ndrange(bounds.shape[0], bounds.shape[1]):
        n = 0
        if bounds[b, k, 0] <= bounds[b, k, 3]:
            L = ti.Vector([views[b, 12], views[b, 13], views[b, 14]])
            Pm = ti.Vector([bounds[b, k, 6], bounds[b, k, 7], bounds[b, k, 8]])
            lo = ti.Vector([bounds[b, k, 0], bounds[b, k, 1], bounds[b, k, 2]])
            hi = ti.Vector([bounds[b, k, 3], bounds[b, k, 4], bounds[b, k, 5]])
            rho = ti.max(hi - Pm, Pm - lo).norm() * 1.001 + 1e-5
            r = (L - Pm).normalized()
            d_cam = deviation(rho, (L - Pm).norm())
            for s in range(src_centres.shape[0]):
                inside = True
                for p in ti.static(range(5)):
                    w = ti.Vector([planes[s, p, 0], planes[s, p, 1], planes[s, p, 2]])
                    # the box corner farthest along the plane normal
                    far_corner = ti.select(w > 0, hi, lo)
                    if w.dot(far_corner) + planes[s, p, 3] < 0:
                        inside = False
                if inside:
                    ds = src_centres[s] - Pm
                    cos_m = ti.min(1.0, ti.max(-1.0, r.dot(ds.normalized())))
                    key = ti.acos(cos_m) - d_cam - deviation(rho, ds.norm()) - 1e-4
                    m = n
                    while m > 0 and keys[b, k, m - 1] > key:
                        lists[b, k, m] = lists[b, k, m - 1]
                        keys[b, k, m] = keys[b, k, m - 1]
                        m -= 1
                    lists[b, k, m] = s
                    keys[b, k, m] = key
                    n += 1
            for m in range(n):
                keys[b, k, m] = ti.cos(ti.min(ti.max(keys[b, k, m], 0.0), 3.14159265))
        n_active[b, k] = n


@ti.func
def deviation(rho: ti.f32, dist: ti.f32) -> ti.f32:
    """Largest change (rad) of the direction towards a point at ``dist`` (m) when the origin
    moves by up to ``rho`` (m)."""
    out = 3.14159265
    if rho < dist:
        out = ti.asin(rho / dist)
    return out


@ti.func
def sees(
    src_proj: ti.template(),
    src_depth: ti.template(),
    s: ti.i32,
    P: ti.template(),
    tol: ti.f32,
    near: ti.f32,
) -> bool:
    """Whether source s sees world point P: in front, inside its image, and not behind its
    depth map by more than the relative tolerance (2x2 neighbourhood maximum)."""
    Hs = src_depth.shape[1]
    Ws = src_depth.shape[2]
    ok = False
    # projection rows K [R | t]: depth first, then u, then v, stopping early
    qz = src_proj[s, 8] * P.x + src_proj[s, 9] * P.y + src_proj[s, 10] * P.z + src_proj[s, 11]
    u = -1.0
    v = -1.0
    if qz > near:
        u = (
            src_proj[s, 0] * P.x + src_proj[s, 1] * P.y + src_proj[s, 2] * P.z + src_proj[s, 3]
        ) / qz
    if u >= 0.0 and u < Ws:
        v = (
            src_proj[s, 4] * P.x + src_proj[s, 5] * P.y + src_proj[s, 6] * P.z + src_proj[s, 7]
        ) / qz
    if v >= 0.0 and v < Hs:
        x0 = ti.max(0, ti.cast(ti.floor(u - 0.5), ti.i32))
        y0 = ti.max(0, ti.cast(ti.floor(v - 0.5), ti.i32))
        x1 = ti.min(Ws - 1, x0 + 1)
        y1 = ti.min(Hs - 1, y0 + 1)
        dmax = ti.max(
            ti.max(src_depth[s, y0, x0], src_depth[s, y0, x1]),
            ti.max(src_depth[s, y1, x0], src_depth[s, y1, x1]),
        )
        ok = qz <= dmax * (1.0 + tol)
    return ok


@ti.kernel
def angles(
    depth: nd(dtype=ti.f32, ndim=3),
    views: nd(dtype=ti.f32, ndim=2),
    src_proj: nd(dtype=ti.f32, ndim=2),
    src_centres: nd(dtype=ti.math.vec3, ndim=1),
    src_depth: nd(dtype=ti.f32, ndim=3),
    tiles_x: ti.i32,
    tiles_y: ti.i32,
    lists: nd(dtype=ti.i32, ndim=3),
    keys: nd(dtype=ti.f32, ndim=3),
    n_active: nd(dtype=ti.i32, ndim=2),
    tol: ti.f32,
    near: ti.f32,
    pix: nd(dtype=ti.f32, ndim=3),
):
    """Per-pixel score (degrees; 180 = seen by no source; -1 = ray hit nothing).

    One task per image row; along the row, the source that gave the previous pixel its best
    angle is tried first (a visible source's angle is an upper bound of the minimum, so the
    search below stops earlier); the result is the exact minimum either way.
    """
    H = depth.shape[1]
    W = depth.shape[2]
    for b, j in ti.ndrange(depth.shape[0], H):
        L = ti.Vector([views[b, 12], views[b, 13], views[b, 14]])
        hint = -1
        for i in range(W):
            z = depth[b, j, i]
            out = -1.0
            if z < FAR:
                P = pixel_point(views, b, j, i, z)
                r = (L - P).normalized()
                kt = (i * tiles_x) // W + tiles_x * ((j * tiles_y) // H)
                best = -2.0  # cosine of the best angle so far; -2 = no source sees P yet
                best_s = -1
                # nested ifs: taichi's `and` does not short-circuit (hint = -1 must not be read)
                if hint >= 0:  # noqa: SIM102
                    if sees(src_proj, src_depth, hint, P, tol, near):
                        d = src_centres[hint] - P
                        best = r.dot(d) / ti.sqrt(d.dot(d) + 1e-30)
                        best_s = hint
                bsq = best * best
                for m in range(n_active[b, kt]):
                    if keys[b, kt, m] <= best:
                        break  # no later source of this tile can beat the best angle
                    s = lists[b, kt, m]
                    d = src_centres[s] - P
                    dt = r.dot(d)
                    n2 = d.dot(d)
                    # "cos(angle) > best" without a square root or a division
                    better = False
                    if best >= 0.0:
                        better = dt > 0.0 and dt * dt > bsq * n2
                    else:
                        better = dt >= 0.0 or dt * dt < bsq * n2
                    if better and s != best_s:  # noqa: SIM102 (sees() is costly: only if better)
                        if sees(src_proj, src_depth, s, P, tol, near):
                            best = dt / ti.sqrt(n2 + 1e-30)
                            bsq = best * best
                            best_s = s
                if best < -1.5:
                    out = 180.0
                else:
                    out = ti.acos(ti.min(1.0, ti.max(-1.0, best))) * 57.29577951308232
                hint = best_s
            pix[b, j, i] = out


@ti.kernel
def view_sums(pix: nd(dtype=ti.f32, ndim=3), sums: nd(dtype=ti.f32, ndim=2)):
    """Per view: sum of hit-pixel scores (deg), hit pixels, and pixels seen by some source."""
    for b in range(pix.shape[0]):
        total = 0.0
        hits = 0
        seen = 0
        for j, i in ti.ndrange(pix.shape[1], pix.shape[2]):
            p = pix[b, j, i]
            if p >= 0.0:
                total += p
                hits += 1
                if p < 179.999:
                    seen += 1
        sums[b, 0] = total
        sums[b, 1] = hits
        sums[b, 2] = seen
