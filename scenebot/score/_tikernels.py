"""Taichi kernels of the score (see :mod:`scenebot.score.kernel` for the definition).

This module must not use ``from __future__ import annotations``: taichi reads the kernel
argument annotations as objects. Kernels are defined at import and compiled at first call,
after :func:`scenebot.score.kernel.init_taichi`.

Two pipelines compute the same scores: the batched passes (:func:`raster`,
:func:`tile_bounds`, :func:`cull`, :func:`angles`, :func:`view_sums`: a thread per chunk of
triangles, tile or pixel row, for GPUs) and :func:`score_per_view` (every pass of a view on
one thread, for CPUs; its functions end in ``_cpu`` or are only called from it).
"""

import taichi as ti

FAR = 1.0e30
RASTER_CHUNK = 64  # triangles per parallel task of the rasterizer
CLUSTER = 32  # consecutive triangles culled together by the per-view (CPU) rasterizer
DMAX_BLOCK = 4  # pixels per side of the blocks of :func:`block_min_max`
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
    R, t = view_rt(views, b)
    fx, fy, cx, cy = views[b, 15], views[b, 16], views[b, 17], views[b, 18]
    sides = frustum_sides(fx, fy, cx, cy, depth.shape[2], depth.shape[1])
    raster_tris(verts, tris, spheres, R, t, fx, fy, cx, cy, sides, depth, near, b, k0, k1, atomic)


@ti.func
def raster_tris(
    verts: ti.template(),
    tris: ti.template(),
    spheres: ti.template(),
    R: ti.template(),
    t: ti.template(),
    fx: ti.f32,
    fy: ti.f32,
    cx: ti.f32,
    cy: ti.f32,
    sides: ti.template(),
    depth: ti.template(),
    near: ti.f32,
    b: ti.i32,
    k0: ti.i32,
    k1: ti.i32,
    atomic: ti.template(),
    one_div: ti.template() = False,
):
    """:func:`raster_range` for the camera (R, t, fx, fy, cx, cy) of view b, whose frustum
    sides are ``sides`` (``one_div``: ``depth`` holds the largest 1 / z, and the triangles
    wholly beyond the near plane go to :func:`raster_triangle_one_div`)."""
    for k in range(k0, k1):
        sc = R @ ti.Vector([spheres[k, 0], spheres[k, 1], spheres[k, 2]]) + t
        if not sphere_outside(sc, spheres[k, 3], near, sides):
            i0, i1, i2 = tris[k, 0], tris[k, 1], tris[k, 2]
            a = R @ ti.Vector([verts[i0, 0], verts[i0, 1], verts[i0, 2]]) + t
            bb = R @ ti.Vector([verts[i1, 0], verts[i1, 1], verts[i1, 2]]) + t
            c = R @ ti.Vector([verts[i2, 0], verts[i2, 1], verts[i2, 2]]) + t
            if ti.static(one_div):
                if ti.min(a.z, bb.z, c.z) > near:
                    raster_triangle_one_div(a, bb, c, b, fx, fy, cx, cy, depth)
                else:
                    raster_triangle(a, bb, c, b, fx, fy, cx, cy, depth, near, False, True)
            else:
                raster_triangle(a, bb, c, b, fx, fy, cx, cy, depth, near, atomic)


@ti.func
def raster_triangle_one_div(
    a: ti.template(),
    bb: ti.template(),
    c: ti.template(),
    b: ti.i32,
    fx: ti.f32,
    fy: ti.f32,
    cx: ti.f32,
    cy: ti.f32,
    depth: ti.template(),
):
    """:func:`raster_triangle` for a triangle wholly beyond the near plane into a buffer of
    the largest 1 / z (:func:`raster_view`): the same edge functions and inside test, and
    1 / z = sum(e_k q_k) of the unnormalised edge functions e_k with q_k = 1 / (z_k area),
    so that a covered pixel costs no division (taichi's fast math turns multiplications by
    a reciprocal into divisions, hence the select that hides them)."""
    H = depth.shape[1]
    W = depth.shape[2]
    u0, v0 = fx * a.x / a.z + cx, fy * a.y / a.z + cy
    u1, v1 = fx * bb.x / bb.z + cx, fy * bb.y / bb.z + cy
    u2, v2 = fx * c.x / c.z + cx, fy * c.y / c.z + cy
    area = (u1 - u0) * (v2 - v0) - (u2 - u0) * (v1 - v0)
    ja = ti.max(0, ti.cast(ti.ceil(ti.min(v0, v1, v2) - 0.5), ti.i32))
    jb = ti.min(H - 1, ti.cast(ti.floor(ti.max(v0, v1, v2) - 0.5), ti.i32))
    ia = ti.max(0, ti.cast(ti.ceil(ti.min(u0, u1, u2) - 0.5), ti.i32))
    ib = ti.min(W - 1, ti.cast(ti.floor(ti.max(u0, u1, u2) - 0.5), ti.i32))
    # a quarter of the small triangles hold no pixel centre: no divisions for them
    if (ja <= jb) & (ia <= ib) & (ti.abs(area) > 1e-12):
        inv_area = 1.0 / area
        q0 = ti.select(area != 0.0, inv_area / a.z, 0.0)
        q1 = ti.select(area != 0.0, inv_area / bb.z, 0.0)
        q2 = ti.select(area != 0.0, inv_area / c.z, 0.0)
        inv_a = ti.select(area != 0.0, inv_area, 0.0)
        eps = -1e-5
        for j in range(ja, jb + 1):
            pv = j + 0.5
            dv0, dv1, dv2 = v0 - pv, v1 - pv, v2 - pv
            for i in range(ia, ib + 1):
                pu = i + 0.5
                e0 = (u1 - pu) * dv2 - (u2 - pu) * dv1
                e1 = (u2 - pu) * dv0 - (u0 - pu) * dv2
                w0 = e0 * inv_a
                w1 = e1 * inv_a
                # no branch: a triangle's edges would mispredict one every few pixels
                inside = (w0 >= eps) & (w1 >= eps) & (1.0 - w0 - w1 >= eps)
                s = e0 * q0 + e1 * q1 + (area - e0 - e1) * q2
                d = depth[b, j, i]
                depth[b, j, i] = ti.select(inside & (s > d), s, d)


@ti.func
def task_view(task: ti.i32, n: ti.i32, n_tasks: ti.i32) -> ti.i32:
    """The view (0..n-1) that parallel task ``task`` of ``n_tasks`` (>= n) starts, or -1.

    Taichi splits a CPU range-for into blocks of at least 512 iterations, which the threads
    take in turn, so a loop over a few hundred views would run on one thread: the per-view
    kernels loop over ``n_tasks`` (``TaichiScorer._n_tasks``: 512 per few views) tasks
    instead, view b in the first of its ``n_tasks / n`` tasks, so that every block holds a
    few views and a thread that runs faster (the other one's core is busy with other work)
    takes more of them. Products in 64 bits: ``task * n`` may pass 2**31.
    """
    b = -1
    t = ti.cast(task, ti.i64)
    first = ti.cast((t * n) // n_tasks, ti.i32)
    if n > 0 and (task == 0 or ti.cast(((t - 1) * n) // n_tasks, ti.i32) != first):
        b = first
    return b


@ti.func
def raster_view(
    verts: ti.template(),
    tris: ti.template(),
    spheres: ti.template(),
    clusters: ti.template(),
    views: ti.template(),
    depth: ti.template(),
    near: ti.f32,
    b: ti.i32,
):
    """The whole z-buffer of view b, by one thread. Clusters of CLUSTER consecutive
    triangles are culled first by their bounding sphere (``clusters`` (C, 4): centre and
    radius, m, enclosing the triangles' own spheres, so that a cluster outside the frustum
    holds no triangle that the per-triangle test keeps). The buffer holds the largest 1 / z
    while the triangles are drawn (no division per covered pixel), then its reciprocal
    (``FAR`` where nothing was drawn): the least z, as the plain z-buffer, since the
    correctly rounded reciprocal is monotonic."""
    # nested loops, not ti.ndrange: an ndrange inside a thread's loop splits a flat index
    # with an integer division and a remainder per pixel
    for j in range(depth.shape[1]):
        for i in range(depth.shape[2]):
            depth[b, j, i] = 0.0  # largest 1 / z so far: nothing
    R, t = view_rt(views, b)
    fx, fy, cx, cy = views[b, 15], views[b, 16], views[b, 17], views[b, 18]
    sides = frustum_sides(fx, fy, cx, cy, depth.shape[2], depth.shape[1])
    T = tris.shape[0]
    for c in range(clusters.shape[0]):
        cc = R @ ti.Vector([clusters[c, 0], clusters[c, 1], clusters[c, 2]]) + t
        if not sphere_outside(cc, clusters[c, 3], near, sides):
            k0 = c * CLUSTER
            k1 = ti.min(T, k0 + CLUSTER)
            raster_tris(
                verts, tris, spheres, R, t, fx, fy, cx, cy, sides, depth, near, b, k0, k1,
                False, True,
            )  # fmt: skip
    # 1 / max(1 / z) = min(z) exactly: the division is monotonic
    for j in range(depth.shape[1]):
        for i in range(depth.shape[2]):
            s = depth[b, j, i]
            depth[b, j, i] = ti.select(s > 0.0, 1.0 / s, FAR)


@ti.kernel
def raster_clustered(
    verts: nd(dtype=ti.f32, ndim=2),
    tris: nd(dtype=ti.i32, ndim=2),
    spheres: nd(dtype=ti.f32, ndim=2),
    clusters: nd(dtype=ti.f32, ndim=2),
    views: nd(dtype=ti.f32, ndim=2),
    depth: nd(dtype=ti.f32, ndim=3),
    n: ti.i32,
    n_tasks: ti.i32,
    near: ti.f32,
):
    """Z-buffers of views 0..n-1 (filled here: no FAR needed beforehand), one thread per
    view (see :func:`task_view` for ``n_tasks``), triangles culled by cluster
    (:func:`raster_view`): for CPUs."""
    for task in range(n_tasks):
        b = task_view(task, n, n_tasks)
        if b >= 0:
            raster_view(verts, tris, spheres, clusters, views, depth, near, b)


@ti.func
def frustum_sides(fx: ti.f32, fy: ti.f32, cx: ti.f32, cy: ti.f32, W: ti.i32, H: ti.i32):
    """Unit normals of the four side planes of a view frustum (camera frame, inside >= 0),
    as the rows (left, right, top, bottom) of a 4x2 matrix."""
    nl = ti.Vector([fx, cx]).normalized()
    nr = ti.Vector([-fx, W - cx]).normalized()
    nt = ti.Vector([fy, cy]).normalized()
    nb = ti.Vector([-fy, H - cy]).normalized()
    return ti.Matrix.rows([nl, nr, nt, nb])


@ti.func
def sphere_outside(sc: ti.template(), rad: ti.f32, near: ti.f32, sides: ti.template()) -> bool:
    """Whether a sphere (camera-frame centre ``sc``, radius ``rad``, m) lies wholly outside
    the frustum whose side normals are ``sides`` (:func:`frustum_sides`) or before ``near``."""
    cut = sc.z < near - rad
    cut |= sides[0, 0] * sc.x + sides[0, 1] * sc.z < -rad
    cut |= sides[1, 0] * sc.x + sides[1, 1] * sc.z < -rad
    cut |= sides[2, 0] * sc.y + sides[2, 1] * sc.z < -rad
    cut |= sides[3, 0] * sc.y + sides[3, 1] * sc.z < -rad
    return cut


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
    inverse: ti.template() = False,
):
    """Write one camera-frame triangle into the z-buffer of view ``b`` (with atomic writes
    when other threads may write the same view; ``inverse``: ``depth`` holds the largest
    1 / z instead, see :func:`raster_view`).

    A triangle wholly beyond the near plane is rasterized with screen-space edge functions
    (pixel centres inside or on an edge; depth from the perspective-correct interpolation of
    1/z, :func:`raster_triangle_beyond`); one that crosses the near plane is clipped by ray
    casting every pixel of its clipped screen bounding box (Moller-Trumbore,
    :func:`raster_triangle_crossing`).
    """
    if ti.min(a.z, bb.z, c.z) > near:
        raster_triangle_beyond(a, bb, c, b, fx, fy, cx, cy, depth, atomic, inverse)
    elif ti.max(a.z, bb.z, c.z) > near:
        raster_triangle_crossing(a, bb, c, b, fx, fy, cx, cy, depth, near, atomic, inverse)


@ti.func
def write_depth(
    depth: ti.template(), b: ti.i32, j: ti.i32, i: ti.i32, z: ti.f32, atomic: ti.template(),
    inverse: ti.template(),
):  # fmt: skip
    """Keep the nearer of pixel (j, i)'s depth and ``z`` in view ``b``'s z-buffer (atomic:
    other threads may write it too; inverse: the buffer holds the largest 1 / z)."""
    if ti.static(atomic):
        ti.atomic_min(depth[b, j, i], z)
    elif ti.static(inverse):
        depth[b, j, i] = ti.max(depth[b, j, i], 1.0 / z)
    else:
        depth[b, j, i] = ti.min(depth[b, j, i], z)


@ti.func
def raster_triangle_beyond(
    a: ti.template(),
    bb: ti.template(),
    c: ti.template(),
    b: ti.i32,
    fx: ti.f32,
    fy: ti.f32,
    cx: ti.f32,
    cy: ti.f32,
    depth: ti.template(),
    atomic: ti.template(),
    inverse: ti.template(),
):
    """:func:`raster_triangle` for a triangle wholly beyond the near plane: screen-space
    edge functions, depth from the perspective-correct interpolation of 1/z."""
    H = depth.shape[1]
    W = depth.shape[2]
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
                    write_depth(depth, b, j, i, z, atomic, inverse)


@ti.func
def clipped_screen_bounds(
    a: ti.template(),
    bb: ti.template(),
    c: ti.template(),
    fx: ti.f32,
    fy: ti.f32,
    cx: ti.f32,
    cy: ti.f32,
    near: ti.f32,
):
    """Screen bounds (umin, umax, vmin, vmax) of the triangle clipped at z = near: its
    projected front vertices and the points where its edges cross the near plane."""
    umin, umax, vmin, vmax = FAR, -FAR, FAR, -FAR
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
    return umin, umax, vmin, vmax


@ti.func
def raster_triangle_crossing(
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
    inverse: ti.template(),
):
    """:func:`raster_triangle` for a triangle that crosses the near plane: the ray of every
    pixel of its clipped screen bounding box cast at it (Moller-Trumbore), hits beyond the
    near plane kept."""
    H = depth.shape[1]
    W = depth.shape[2]
    umin, umax, vmin, vmax = clipped_screen_bounds(a, bb, c, fx, fy, cx, cy, near)
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
                    write_depth(depth, b, j, i, z, atomic, inverse)


@ti.func
def view_camera(views: ti.template(), b: ti.i32):
    """Camera of view b: rotation R, translation t (cam_from_world), centre L (m) and
    intrinsics (fx, fy, cx, cy), loaded once for all of the view's pixels."""
    R, t = view_rt(views, b)
    L = ti.Vector([views[b, 12], views[b, 13], views[b, 14]])
    K = ti.Vector([views[b, 15], views[b, 16], views[b, 17], views[b, 18]])
    return R, t, L, K


@ti.func
def pixel_point(R: ti.template(), t: ti.template(), K: ti.template(), j, i, z):
    """World point (m) of pixel (j, i) at z-depth z of the camera (R, t, K = fx, fy, cx, cy)."""
    pc = ti.Vector([(i + 0.5 - K[2]) / K[0] * z, (j + 0.5 - K[3]) / K[1] * z, z])
    return R.transpose() @ (pc - t)


@ti.func
def tile_bound(
    depth: ti.template(),
    R: ti.template(),
    t: ti.template(),
    K: ti.template(),
    b: ti.i32,
    k: ti.i32,
    tiles_x: ti.i32,
    tiles_y: ti.i32,
    bounds: ti.template(),
):
    """Bounds of the hit points of tile k of view b (see :func:`tile_bounds`)."""
    H = depth.shape[1]
    W = depth.shape[2]
    kx = k % tiles_x
    ky = k // tiles_x
    lo = ti.Vector([FAR, FAR, FAR])
    hi = ti.Vector([-FAR, -FAR, -FAR])
    acc = ti.Vector([0.0, 0.0, 0.0])
    n = 0
    for j in range((ky * H + tiles_y - 1) // tiles_y, ((ky + 1) * H + tiles_y - 1) // tiles_y):
        for i in range((kx * W + tiles_x - 1) // tiles_x, ((kx + 1) * W + tiles_x - 1) // tiles_x):
            z = depth[b, j, i]
            if z < FAR:
                P = pixel_point(R, t, K, j, i, z)
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
    for b, k in ti.ndrange(bounds.shape[0], bounds.shape[1]):
        R, t, _, K = view_camera(views, b)
        tile_bound(depth, R, t, K, b, k, tiles_x, tiles_y, bounds)


@ti.func
def cull_tile(
    bounds: ti.template(),
    L: ti.template(),
    src_centres: ti.template(),
    planes: ti.template(),
    lists: ti.template(),
    keys: ti.template(),
    n_active: ti.template(),
    b: ti.i32,
    k: ti.i32,
):
    """Sorted source list of tile k of view b, camera centre L (see :func:`cull`)."""
    n = 0
    if bounds[b, k, 0] <= bounds[b, k, 3]:
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
        L = ti.Vector([views[b, 12], views[b, 13], views[b, 14]])
        cull_tile(bounds, L, src_centres, planes, lists, keys, n_active, b, k)


@ti.func
def deviation(rho: ti.f32, dist: ti.f32) -> ti.f32:
    """Largest change (rad) of the direction towards a point at ``dist`` (m) when the origin
    moves by up to ``rho`` (m)."""
    out = 3.14159265
    if rho < dist:
        out = ti.asin(rho / dist)
    return out


@ti.func
def project(src_proj: ti.template(), s: ti.i32, P: ti.template(), near: ti.f32, Ws: ti.i32):
    """``(depth, u, v)`` of world point P in source s (projection rows K [R | t]): depth
    first, then u, then v, stopping early (u, v stay -1 where the point is behind the camera
    or left or right of the image)."""
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
    return ti.Vector([qz, u, v])


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
    q = project(src_proj, s, P, near, Ws)
    qz, u, v = q[0], q[1], q[2]
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
def neighbourhood_max(depth: nd(dtype=ti.f32, ndim=3), out: nd(dtype=ti.f32, ndim=3)):
    """``out[s, y, x]``: the largest of ``depth[s]`` at (y, x), (y, x + 1), (y + 1, x) and
    (y + 1, x + 1), indices clamped to the image (the 2x2 neighbourhood of :func:`sees`)."""
    Hs = depth.shape[1]
    Ws = depth.shape[2]
    for s, y0, x0 in ti.ndrange(depth.shape[0], Hs, Ws):
        x1 = ti.min(Ws - 1, x0 + 1)
        y1 = ti.min(Hs - 1, y0 + 1)
        out[s, y0, x0] = ti.max(
            ti.max(depth[s, y0, x0], depth[s, y0, x1]),
            ti.max(depth[s, y1, x0], depth[s, y1, x1]),
        )


@ti.kernel
def block_min_max(dmax: nd(dtype=ti.f32, ndim=3), out: nd(dtype=ti.math.vec2, ndim=3)):
    """``out[s, by, bx]``: the least and the largest of ``dmax[s]`` over the block of
    DMAX_BLOCK x DMAX_BLOCK pixels (by, bx) (clipped to the image)."""
    Hs = dmax.shape[1]
    Ws = dmax.shape[2]
    for s, by, bx in ti.ndrange(out.shape[0], out.shape[1], out.shape[2]):
        lo = FAR * 4.0
        hi = -FAR
        for y in range(by * DMAX_BLOCK, ti.min(Hs, (by + 1) * DMAX_BLOCK)):
            for x in range(bx * DMAX_BLOCK, ti.min(Ws, (bx + 1) * DMAX_BLOCK)):
                lo = ti.min(lo, dmax[s, y, x])
                hi = ti.max(hi, dmax[s, y, x])
        out[s, by, bx] = ti.Vector([lo, hi])


@ti.func
def sees_max(
    src_proj: ti.template(),
    src_dmax: ti.template(),
    src_mm: ti.template(),
    s: ti.i32,
    P: ti.template(),
    tol: ti.f32,
    near: ti.f32,
) -> bool:
    """:func:`sees` reading the 2x2 maximum of :func:`neighbourhood_max` (one load, the same
    value), and only where the least and largest of them over its block (``src_mm``,
    :func:`block_min_max`, 16 times smaller, so mostly in cache) do not decide already."""
    Hs = src_dmax.shape[1]
    Ws = src_dmax.shape[2]
    ok = False
    q = project(src_proj, s, P, near, Ws)
    qz, u, v = q[0], q[1], q[2]
    if v >= 0.0 and v < Hs:
        x0 = ti.max(0, ti.cast(ti.floor(u - 0.5), ti.i32))
        y0 = ti.max(0, ti.cast(ti.floor(v - 0.5), ti.i32))
        # the block's least and largest 2x2 maxima decide most points without the full map
        mm = src_mm[s, y0 // DMAX_BLOCK, x0 // DMAX_BLOCK]
        if qz <= mm[0] * (1.0 + tol):
            ok = True
        elif qz <= mm[1] * (1.0 + tol):
            ok = qz <= src_dmax[s, y0, x0] * (1.0 + tol)
    return ok


@ti.func
def at_centre(C: ti.template(), best_c: ti.template()) -> bool:
    """Whether camera centre C is ``best_c``, the centre of the source that gives the best
    angle so far: C then forms the same angle (up to the rounding of another code path), so
    it cannot lower the minimum and its visibility need not be tested. The cameras of a
    photo ring share one centre, and those sharing the best one's centre follow it in a
    tile's list (equal keys): they were 40 % of the search's visibility tests in the
    benchmark."""
    return (C[0] == best_c[0]) & (C[1] == best_c[1]) & (C[2] == best_c[2])


@ti.func
def angle_row(
    depth: ti.template(),
    R: ti.template(),
    t: ti.template(),
    L: ti.template(),
    K: ti.template(),
    src_proj: ti.template(),
    src_centres: ti.template(),
    src_depth: ti.template(),
    tiles_x: ti.i32,
    tiles_y: ti.i32,
    lists: ti.template(),
    keys: ti.template(),
    n_active: ti.template(),
    tol: ti.f32,
    near: ti.f32,
    pix: ti.template(),
    b: ti.i32,
    j: ti.i32,
):
    """Pixel scores of row j of view b (see :func:`angles`)."""
    H = depth.shape[1]
    W = depth.shape[2]
    hint = -1
    for i in range(W):
        z = depth[b, j, i]
        out = -1.0
        if z < FAR:
            P = pixel_point(R, t, K, j, i, z)
            r = (L - P).normalized()
            kt = (i * tiles_x) // W + tiles_x * ((j * tiles_y) // H)
            best = -2.0  # cosine of the best angle so far; -2 = no source sees P yet
            best_s = -1
            best_c = ti.Vector([FAR, FAR, FAR])  # best_s's centre (none yet: no camera's)
            # nested ifs: taichi's `and` does not short-circuit (hint = -1 must not be read)
            if hint >= 0:  # noqa: SIM102
                if sees(src_proj, src_depth, hint, P, tol, near):
                    best_c = src_centres[hint]
                    d = best_c - P
                    best = r.dot(d) / ti.sqrt(d.dot(d) + 1e-30)
                    best_s = hint
            bsq = best * best
            for m in range(n_active[b, kt]):
                if keys[b, kt, m] <= best:
                    break  # no later source of this tile can beat the best angle
                s = lists[b, kt, m]
                C = src_centres[s]
                d = C - P
                dt = r.dot(d)
                n2 = d.dot(d)
                # "cos(angle) > best" without a square root or a division
                better = False
                if best >= 0.0:
                    better = dt > 0.0 and dt * dt > bsq * n2
                else:
                    better = dt >= 0.0 or dt * dt < bsq * n2
                # sees() is costly: only if better, and not for a camera at the best one's
                # centre (photo rings), whose angle is the same
                if better and not at_centre(C, best_c):  # noqa: SIM102
                    if sees(src_proj, src_depth, s, P, tol, near):
                        best = dt / ti.sqrt(n2 + 1e-30)
                        bsq = best * best
                        best_s = s
                        best_c = C
            if best < -1.5:
                out = 180.0
            else:
                out = ti.acos(ti.min(1.0, ti.max(-1.0, best))) * 57.29577951308232
            hint = best_s
        pix[b, j, i] = out


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
    for b, j in ti.ndrange(depth.shape[0], depth.shape[1]):
        R, t, L, K = view_camera(views, b)
        angle_row(
            depth, R, t, L, K, src_proj, src_centres, src_depth, tiles_x, tiles_y,
            lists, keys, n_active, tol, near, pix, b, j,
        )  # fmt: skip


@ti.func
def view_sum(pix: ti.template(), sums: ti.template(), b: ti.i32):
    """Sums of view b (see :func:`view_sums`)."""
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


@ti.kernel
def view_sums(pix: nd(dtype=ti.f32, ndim=3), sums: nd(dtype=ti.f32, ndim=2)):
    """Per view: sum of hit-pixel scores (deg), hit pixels, and pixels seen by some source."""
    for b in range(pix.shape[0]):
        view_sum(pix, sums, b)


@ti.func
def view_rays(R: ti.template(), K: ti.template()):
    """(D0, Dx, Dy): the world-frame ray of pixel centre (j, i), scaled to unit camera z, is
    D0 + i Dx + j Dy, so that the point at z-depth z is L + z (D0 + i Dx + j Dy) and the
    direction from it towards the camera centre L is that of -(D0 + i Dx + j Dy)."""
    Dx = ti.Vector([R[0, 0], R[0, 1], R[0, 2]]) / K[0]
    Dy = ti.Vector([R[1, 0], R[1, 1], R[1, 2]]) / K[1]
    D0 = ti.Vector([R[2, 0], R[2, 1], R[2, 2]]) + (0.5 - K[2]) * Dx + (0.5 - K[3]) * Dy
    return D0, Dx, Dy


@ti.func
def tile_bound_cpu(
    depth: ti.template(),
    L: ti.template(),
    D0: ti.template(),
    Dx: ti.template(),
    Dy: ti.template(),
    b: ti.i32,
    k: ti.i32,
    tiles_x: ti.i32,
    tiles_y: ti.i32,
    bounds: ti.template(),
):
    """:func:`tile_bound` with the points of :func:`view_rays` (as :func:`angle_row_cpu`)."""
    H = depth.shape[1]
    W = depth.shape[2]
    kx = k % tiles_x
    ky = k // tiles_x
    lo = ti.Vector([FAR, FAR, FAR])
    hi = ti.Vector([-FAR, -FAR, -FAR])
    acc = ti.Vector([0.0, 0.0, 0.0])
    n = 0
    for j in range((ky * H + tiles_y - 1) // tiles_y, ((ky + 1) * H + tiles_y - 1) // tiles_y):
        Dj = D0 + j * Dy
        for i in range((kx * W + tiles_x - 1) // tiles_x, ((kx + 1) * W + tiles_x - 1) // tiles_x):
            z = depth[b, j, i]
            if z < FAR:
                P = L + z * (Dj + i * Dx)
                lo = ti.min(lo, P)
                hi = ti.max(hi, P)
                acc += P
                n += 1
    acc /= ti.max(n, 1)
    for c in ti.static(range(3)):
        bounds[b, k, c] = lo[c]
        bounds[b, k, c + 3] = hi[c]
        bounds[b, k, c + 6] = acc[c]


@ti.func
def box_in_frustum(planes: ti.template(), s: ti.i32, lo: ti.template(), hi: ti.template()) -> bool:
    """Whether the box [lo, hi] may hold a point inside source s's frustum (``planes``, see
    :func:`cull`): False when it lies wholly outside one of the planes."""
    inside = True
    for p in ti.static(range(5)):
        w = ti.Vector([planes[s, p, 0], planes[s, p, 1], planes[s, p, 2]])
        # the box corner farthest along the plane normal
        far_corner = ti.select(w > 0, hi, lo)
        inside &= w.dot(far_corner) + planes[s, p, 3] >= 0
    return inside


@ti.func
def camera_deviation(
    R: ti.template(), K: ti.template(), r: ti.template(), dist, rho, i0, i1, j0, j1
):
    """Cosine and sine of the largest angle between the direction ``r`` (world frame, unit)
    from the tile's mean point towards the camera, at distance ``dist``, and the direction
    towards the camera from any point of the tile (box radius ``rho``, pixels i0..i1,
    j0..j1): the smaller of asin(rho / dist) and the largest angle between ``r`` and the rays
    of the tile's four corner pixels (every point of the tile is on a ray in between, and the
    angle to a point inside a convex cone of rays is largest at a corner). (-1, 0) when
    neither bound holds (the angle may reach pi)."""
    c = -1.0
    sn = 0.0
    if rho < dist:
        sn = rho / dist
        c = ti.sqrt(ti.max(0.0, 1.0 - sn * sn))
    rc = R @ r  # camera frame
    cc = 1.0
    sc = 0.0
    for q in ti.static(range(4)):
        i = i0 if ti.static(q % 2 == 0) else i1
        j = j0 if ti.static(q // 2 == 0) else j1
        d = -ti.Vector([(i + 0.5 - K[2]) / K[0], (j + 0.5 - K[3]) / K[1], 1.0])
        inv = 1.0 / d.norm()
        cq = d.dot(rc) * inv
        sq = ti.min(1.0, d.cross(rc).norm() * inv)  # accurate for small angles, unlike cq
        # the corner farthest from r: the least cosine (and -1 once a corner is >= 90 deg)
        worse = cq < cc
        cc = ti.select(worse, cq, cc)
        sc = ti.select(worse, sq, sc)
    if cc <= 0.0:
        cc = -1.0
    if cc > c:  # the corner bound is the smaller angle
        c = cc
        sn = sc
    return c, sn


@ti.func
def cull_view(
    R: ti.template(),
    L: ti.template(),
    K: ti.template(),
    b: ti.i32,
    W: ti.i32,
    H: ti.i32,
    tiles_x: ti.i32,
    tiles_y: ti.i32,
    bounds: ti.template(),
    src_centres: ti.template(),
    planes: ti.template(),
    near_srcs: ti.template(),
    lists: ti.template(),
    tsrc: ti.template(),
    groups: ti.template(),
    n_active: ti.template(),
):
    """The sorted source list of every tile of view b (one thread; see :func:`cull` for the
    definition), with less work:

    - the sources are tested against the box of the whole view, those kept against the box
      of each block of 2x2 tiles, and those kept against each of its tiles (a box inside a
      bigger one is outside a plane only if the bigger one is), so the lists are the same;
    - the camera's share of the lower bound of a source's angle is the smaller of
      asin(rho / |L - Pm|) and the largest angle between L - Pm and the rays of the tile's
      corner pixels (:func:`camera_deviation`);
    - the cosine of the bound, cos(theta_m - delta), is formed from the cosines and sines of
      theta_m and of the deviations by the angle-sum rules (no inverse trigonometry); sources
      with theta_m <= delta get keys >= 1 (never a reason to stop), ordered by
      cos theta_m - cos delta;
    - the list holds groups of cameras at one centre (:func:`cull_tile_cpu`): ``tsrc``
      (B, tiles, S) receives each group's centre and key side by side, ``groups`` the range
      of its cameras in ``lists``.

    ``near_srcs`` (B, 2 S) is scratch: the view's sources, then the block's.
    """
    S = src_centres.shape[0]
    vlo = ti.Vector([FAR, FAR, FAR])
    vhi = ti.Vector([-FAR, -FAR, -FAR])
    for k in range(tiles_x * tiles_y):
        for c in ti.static(range(3)):
            vlo[c] = ti.min(vlo[c], bounds[b, k, c])
            vhi[c] = ti.max(vhi[c], bounds[b, k, c + 3])
    nv = 0
    if vlo[0] <= vhi[0]:
        for s in range(S):
            near_srcs[b, nv] = s  # kept if inside: no branch
            nv += ti.cast(box_in_frustum(planes, s, vlo, vhi), ti.i32)
    for gy in range((tiles_y + 1) // 2):
        for gx in range((tiles_x + 1) // 2):
            glo = ti.Vector([FAR, FAR, FAR])
            ghi = ti.Vector([-FAR, -FAR, -FAR])
            for q in ti.static(range(4)):
                kx = 2 * gx + q % 2
                ky = 2 * gy + q // 2
                if kx < tiles_x and ky < tiles_y:
                    k = kx + tiles_x * ky
                    for c in ti.static(range(3)):
                        glo[c] = ti.min(glo[c], bounds[b, k, c])
                        ghi[c] = ti.max(ghi[c], bounds[b, k, c + 3])
            ng = 0
            if glo[0] <= ghi[0]:
                for g in range(nv):
                    s = near_srcs[b, g]
                    near_srcs[b, S + ng] = s
                    ng += ti.cast(box_in_frustum(planes, s, glo, ghi), ti.i32)
            for q in ti.static(range(4)):
                kx = 2 * gx + q % 2
                ky = 2 * gy + q // 2
                if kx < tiles_x and ky < tiles_y:
                    k = kx + tiles_x * ky
                    i0 = (kx * W + tiles_x - 1) // tiles_x
                    i1 = ((kx + 1) * W + tiles_x - 1) // tiles_x - 1
                    j0 = (ky * H + tiles_y - 1) // tiles_y
                    j1 = ((ky + 1) * H + tiles_y - 1) // tiles_y - 1
                    cull_tile_cpu(
                        R, L, K, b, k, i0, i1, j0, j1, bounds, src_centres, planes, near_srcs,
                        ng, lists, tsrc, groups, n_active,
                    )  # fmt: skip


@ti.func
def cull_tile_cpu(
    R: ti.template(),
    L: ti.template(),
    K: ti.template(),
    b: ti.i32,
    k: ti.i32,
    i0: ti.i32,
    i1: ti.i32,
    j0: ti.i32,
    j1: ti.i32,
    bounds: ti.template(),
    src_centres: ti.template(),
    planes: ti.template(),
    near_srcs: ti.template(),
    ng: ti.i32,
    lists: ti.template(),
    tsrc: ti.template(),
    groups: ti.template(),
    n_active: ti.template(),
):
    """Sorted list of tile k (pixels i0..i1, j0..j1) of view b among the ``ng`` sources of
    ``near_srcs[b, S:]`` (see :func:`cull_view`), by groups of cameras at one centre.

    The angle of a source depends on its centre only, and the cameras of a photo ring share
    one: consecutive kept sources (in source order) at the same centre form one group, with
    one key (computed once) and one entry of the sorted list, so that a pixel's search
    passes a centre once however many of its cameras the tile holds. ``lists[b, k]`` holds
    the kept sources in source order (the groups' members), ``tsrc[b, k, g]`` the centre and
    key of the g-th group in key order, ``groups[b, k, g]`` the range of its members in
    ``lists[b, k]``, and ``n_active[b, k]`` the number of groups."""
    S = src_centres.shape[0]
    n = 0  # groups
    n_mem = 0  # members
    last_c = ti.Vector([FAR, FAR, FAR])  # centre of the last kept source (none yet)
    last_g = 0  # its group's place in the sorted list (no group has been inserted since)
    if bounds[b, k, 0] <= bounds[b, k, 3]:
        Pm = ti.Vector([bounds[b, k, 6], bounds[b, k, 7], bounds[b, k, 8]])
        lo = ti.Vector([bounds[b, k, 0], bounds[b, k, 1], bounds[b, k, 2]])
        hi = ti.Vector([bounds[b, k, 3], bounds[b, k, 4], bounds[b, k, 5]])
        rho = ti.max(hi - Pm, Pm - lo).norm() * 1.001 + 1e-5
        dist = (L - Pm).norm()
        r = (L - Pm) / dist
        c0, s0 = camera_deviation(R, K, r, dist, rho, i0, i1, j0, j1)
        # delta_1 = camera deviation + 1e-4 (cos 1e-4 = 1 - 5e-9: 1 in float32)
        c1 = c0 - s0 * 1e-4
        s1 = s0 + c0 * 1e-4
        for g in range(ng):
            s = near_srcs[b, S + g]
            if box_in_frustum(planes, s, lo, hi):
                C = src_centres[s]
                lists[b, k, n_mem] = s
                n_mem += 1
                if at_centre(C, last_c):  # the last group's centre: one more member
                    groups[b, k, last_g][1] = n_mem
                else:
                    ds = C - Pm
                    dn = ds.norm()
                    cos_m = ti.min(1.0, ti.max(-1.0, r.dot(ds) / dn))
                    # cos and sin of delta = delta_1 + asin(rho / dn)
                    key = 3.0 + cos_m  # delta >= pi: no bound
                    if rho < dn and c0 > -1.0:
                        s2 = rho / dn
                        c2 = ti.sqrt(ti.max(0.0, 1.0 - s2 * s2))
                        cd = c1 * c2 - s1 * s2
                        sd = s1 * c2 + c1 * s2
                        if sd >= 0.0:
                            if cos_m < cd:  # theta_m > delta: cos(theta_m - delta)
                                sin_m = ti.sqrt(ti.max(0.0, 1.0 - cos_m * cos_m))
                                key = ti.min(1.0, cos_m * cd + sin_m * sd + 1e-6)
                            else:
                                key = 1.0 + (cos_m - cd)
                    m = n
                    while m > 0 and tsrc[b, k, m - 1][3] < key:
                        groups[b, k, m] = groups[b, k, m - 1]
                        tsrc[b, k, m] = tsrc[b, k, m - 1]
                        m -= 1
                    groups[b, k, m] = ti.Vector([n_mem - 1, n_mem])
                    tsrc[b, k, m] = ti.Vector([C.x, C.y, C.z, key])
                    n += 1
                    last_c = C
                    last_g = m
    n_active[b, k] = n


@ti.func
def acos_poly(x: ti.f32) -> ti.f32:
    """acos(x) (rad) for x in [-1, 1], within 5e-7 rad (3e-5 degrees; libm's acosf: 2e-7)
    and to 2e-7 of the angle near x = 1: Abramowitz and Stegun 4.4.46, sqrt(1 - |x|) times a
    polynomial of degree 7 in |x| (error 2e-8), and pi minus that for x < 0: inline, where
    libm's acosf is a call (a tenth of the samples of a profile of the CPU pass)."""
    ax = ti.abs(x)
    p = -0.0012624911
    p = p * ax + 0.0066700901
    p = p * ax - 0.0170881256
    p = p * ax + 0.0308918810
    p = p * ax - 0.0501743046
    p = p * ax + 0.0889789874
    p = p * ax - 0.2145988016
    p = p * ax + 1.5707963050
    r = ti.sqrt(1.0 - ax) * p
    return ti.select(x < 0.0, 3.14159265358979 - r, r)


@ti.func
def angle_row_cpu(
    depth: ti.template(),
    L: ti.template(),
    D0: ti.template(),
    Dx: ti.template(),
    Dy: ti.template(),
    src_proj: ti.template(),
    src_dmax: ti.template(),
    src_mm: ti.template(),
    tiles_x: ti.i32,
    tiles_y: ti.i32,
    lists: ti.template(),
    tsrc: ti.template(),
    groups: ti.template(),
    n_active: ti.template(),
    tol: ti.f32,
    near: ti.f32,
    pix: ti.template(),
    b: ti.i32,
    j: ti.i32,
):
    """:func:`angle_row` for one thread that owns the whole view (camera loaded once, points
    from :func:`view_rays`), reading the tiles' lists of groups of cameras at one centre
    (centre and key, and the cameras) of :func:`cull_view` and the 2x2 maxima of the source
    depth maps (:func:`sees_max`).

    ``pix[b, j]`` receives the cosine of each pixel's best angle (-2: no source sees the
    point, -3: the ray hits nothing); :func:`view_degrees` turns them into degrees."""
    H = depth.shape[1]
    W = depth.shape[2]
    hint = -1
    hint_c = ti.Vector([0.0, 0.0, 0.0])
    k_row = tiles_x * ((j * tiles_y) // H)
    kx = 0
    i_next = (W + tiles_x - 1) // tiles_x  # first column of tile kx + 1
    Dj = D0 + j * Dy
    for i in range(W):
        if i >= i_next:
            kx += 1
            i_next = ((kx + 1) * W + tiles_x - 1) // tiles_x
        z = depth[b, j, i]
        out = -3.0
        if z < FAR:
            D = Dj + i * Dx
            P = L + z * D
            # the direction towards L, not normalised: cos(angle) = r.d / sqrt(DD d.d)
            r = -D
            DD = D.dot(D)
            kt = kx + k_row
            best = -2.0  # cosine of the best angle so far; -2 = no source sees P yet
            best_s = -1
            best_c = ti.Vector([FAR, FAR, FAR])  # best_s's centre (none yet: no camera's)
            # nested ifs: taichi's `and` does not short-circuit (hint = -1 must not be read)
            if hint >= 0:  # noqa: SIM102
                if sees_max(src_proj, src_dmax, src_mm, hint, P, tol, near):
                    d = hint_c - P
                    best = r.dot(d) / ti.sqrt(DD * d.dot(d) + 1e-30)
                    best_s = hint
                    best_c = hint_c
            bsq = best * best * DD
            for m in range(n_active[b, kt]):
                e = tsrc[b, kt, m]
                if e[3] <= best:
                    break  # no later source of this tile can beat the best angle
                C = ti.Vector([e[0], e[1], e[2]])
                d = C - P
                dt = r.dot(d)
                n2 = d.dot(d)
                # "cos(angle) > best" without a square root or a division (bsq: best^2 DD)
                better = False
                if best >= 0.0:
                    better = dt > 0.0 and dt * dt > bsq * n2
                else:
                    better = dt >= 0.0 or dt * dt < bsq * n2
                # sees() is costly: only if better, and not at the best one's centre (the
                # same angle); then the group's cameras in turn until one sees P
                if better and not at_centre(C, best_c):
                    grp = groups[b, kt, m]
                    for q in range(grp[0], grp[1]):
                        s = lists[b, kt, q]
                        if sees_max(src_proj, src_dmax, src_mm, s, P, tol, near):
                            best = dt / ti.sqrt(DD * n2 + 1e-30)
                            bsq = best * best * DD
                            best_s = s
                            best_c = C
                            break
            out = best
            hint = best_s
            hint_c = best_c
        pix[b, j, i] = out


@ti.func
def cosine_degrees(c: ti.f32) -> ti.f32:
    """The pixel score (degrees, as :func:`angles`; -1: the ray hit nothing) of a cosine that
    :func:`angle_row_cpu` found (-2: no source sees the point, -3: no hit)."""
    deg = acos_poly(ti.min(1.0, ti.max(-1.0, c))) * 57.29577951308232
    return ti.select(c < -2.5, -1.0, ti.select(c < -1.5, 180.0, deg))


@ti.func
def view_degrees(pix: ti.template(), sums: ti.template(), b: ti.i32):
    """The sums of view b (see :func:`view_sums`) from the cosines that :func:`angle_row_cpu`
    leaves in ``pix[b]`` (:func:`pixel_degrees` turns those into degrees where the pixels
    are wanted).

    A pass of its own, with no branch, rather than inside the search, where the arc cosine's
    latency held up the next pixel's work; and one that stores nothing, so that the compiler
    keeps every array's address and shape out of the loop (a store might change them, it
    assumes) and runs it on vectors of pixels (the sums add in another order than pixel by
    pixel: float32 rounding, 1e-5 degrees of a view's score)."""
    total = 0.0
    hits = 0
    seen = 0
    for j in range(pix.shape[1]):
        row_total = 0.0
        for i in range(pix.shape[2]):
            c = pix[b, j, i]
            out = cosine_degrees(c)
            hit = c > -2.5
            row_total += ti.select(hit, out, 0.0)
            hits += ti.cast(hit, ti.i32)
            seen += ti.cast(hit & (out < 179.999), ti.i32)
        total += row_total
    sums[b, 0] = total
    sums[b, 1] = hits
    sums[b, 2] = seen


@ti.kernel
def pixel_degrees(pix: nd(dtype=ti.f32, ndim=3), n: ti.i32):
    """Pixel scores (degrees) of views 0..n-1 from the cosines of :func:`score_per_view`."""
    for b, j, i in ti.ndrange(n, pix.shape[1], pix.shape[2]):
        pix[b, j, i] = cosine_degrees(pix[b, j, i])


@ti.kernel
def score_per_view(
    verts: nd(dtype=ti.f32, ndim=2),
    tris: nd(dtype=ti.i32, ndim=2),
    spheres: nd(dtype=ti.f32, ndim=2),
    clusters: nd(dtype=ti.f32, ndim=2),
    views: nd(dtype=ti.f32, ndim=2),
    n: ti.i32,
    n_tasks: ti.i32,
    near: ti.f32,
    depth: nd(dtype=ti.f32, ndim=3),
    tiles_x: ti.i32,
    tiles_y: ti.i32,
    bounds: nd(dtype=ti.f32, ndim=3),
    src_centres: nd(dtype=ti.math.vec3, ndim=1),
    planes: nd(dtype=ti.f32, ndim=3),
    near_srcs: nd(dtype=ti.i32, ndim=2),
    lists: nd(dtype=ti.i32, ndim=3),
    tsrc: nd(dtype=ti.math.vec4, ndim=3),
    groups: nd(dtype=ti.math.ivec2, ndim=3),
    n_active: nd(dtype=ti.i32, ndim=2),
    src_proj: nd(dtype=ti.f32, ndim=2),
    src_dmax: nd(dtype=ti.f32, ndim=3),
    src_mm: nd(dtype=ti.math.vec2, ndim=3),
    tol: ti.f32,
    pix: nd(dtype=ti.f32, ndim=3),
    sums: nd(dtype=ti.f32, ndim=2),
):
    """All passes of the score for views 0..n-1, one thread per view (see :func:`task_view`
    for ``n_tasks``): for CPUs.

    The same computation as :func:`raster`, :func:`tile_bounds`, :func:`cull`,
    :func:`angles` and :func:`view_sums` in turn, but each view's z-buffer, tile lists and
    pixel scores are made and used by one thread while they are in its cache, a batch costs
    one launch, triangles are culled by cluster first (:func:`raster_view`) and sources by
    blocks of tiles first (:func:`cull_view`).
    """
    H = depth.shape[1]
    W = depth.shape[2]
    for task in range(n_tasks):
        b = task_view(task, n, n_tasks)
        if b >= 0:
            raster_view(verts, tris, spheres, clusters, views, depth, near, b)
            R, _, L, K = view_camera(views, b)
            D0, Dx, Dy = view_rays(R, K)
            for k in range(bounds.shape[1]):
                tile_bound_cpu(depth, L, D0, Dx, Dy, b, k, tiles_x, tiles_y, bounds)
            cull_view(
                R, L, K, b, W, H, tiles_x, tiles_y, bounds, src_centres, planes, near_srcs,
                lists, tsrc, groups, n_active,
            )  # fmt: skip
            for j in range(H):
                angle_row_cpu(
                    depth, L, D0, Dx, Dy, src_proj, src_dmax, src_mm, tiles_x, tiles_y, lists,
                    tsrc, groups, n_active, tol, near, pix, b, j,
                )  # fmt: skip
            view_degrees(pix, sums, b)
