"""The rendering-quality score: taichi kernel against the numpy reference and ground truth."""

import os

import numpy as np
import pytest

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")

from scenebot.score.geometry import candidate_views
from scenebot.score.kernel import init_taichi
from scenebot.testing import score as syn

RING_CENTRES = [[-1.5, -0.5], [0.0, 0.5], [1.5, -1.0], [-0.5, -1.2], [2.0, 1.0]]


@pytest.fixture(scope="module")
def office():
    V, F = syn.room(cell_m=0.5)
    R, t, poses = syn.ring_sources(RING_CENTRES, 12)
    return V, F, R, t, poses


def random_poses(n, rng, half=(2.3, 1.5)):
    return np.stack(
        [
            rng.uniform(-half[0], half[0], n),
            rng.uniform(-half[1], half[1], n),
            rng.uniform(-np.pi, np.pi, n),
        ],
        1,
    )


def test_taichi_starts_without_gpu():
    arch = init_taichi("auto")
    assert arch in ("x64", "arm64", "cuda", "vulkan")


def test_kernel_matches_reference(office):
    V, F, R, t, _ = office
    tk, ref = syn.scorers(V, F, R, t, 40, 30, batch_size=16, backend="cpu")
    poses = random_poses(24, np.random.default_rng(3))  # two batches, the second one partial
    a = tk.score(poses, return_pixels=True)
    b = ref.score(poses, return_pixels=True)
    assert np.all(np.isfinite(a.score_deg))
    assert np.mean(np.abs(a.score_deg - b.score_deg)) <= 0.5
    hit_a, hit_b = a.pixels >= 0, b.pixels >= 0
    assert np.mean(hit_a == hit_b) > 0.995
    both = hit_a & hit_b
    assert np.mean(np.abs(a.pixels - b.pixels)[both] < 1.0) > 0.99
    np.testing.assert_allclose(a.hit_fraction, b.hit_fraction, atol=0.01)


def test_source_depth_maps_match_ray_casting(office):
    V, F, R, t, _ = office
    tk, ref = syn.scorers(V, F, R[:8], t[:8], 40, 30, depth_width=64, backend="cpu")
    dt, dr = tk.source_depth_maps(), ref.src_depth
    both = (dt < 1e29) & np.isfinite(dr)
    assert both.mean() > 0.99  # closed room: nearly every ray hits
    np.testing.assert_allclose(dt[both], dr[both], rtol=1e-4, atol=1e-4)


def test_candidate_at_source_pose_scores_zero_where_it_sees(office):
    V, F, R, t, poses = office
    tk, ref = syn.scorers(V, F, R, t, 80, 60, backend="cpu")
    for scorer in (tk, ref):
        res = scorer.score(poses[[5, 17, 40]], return_pixels=True)
        for pix in res.pixels:
            hit = pix[pix >= 0]
            assert hit.size > 0.95 * pix.size
            # every hit pixel is seen by the source at this very pose, along the same ray
            assert np.mean(hit < 0.5) > 0.98
            assert np.median(hit) < 0.05


def test_uncovered_half_scores_worse():
    V, F = syn.room(cell_m=0.5, furniture=False)
    # all photos taken in the west half, looking west: the east half is never photographed
    th = np.deg2rad(np.arange(120, 241, 15))
    poses = np.array([(x, y, a) for x in (-2.0, -1.0) for y in (-1.0, 0.0, 1.0) for a in th])
    from scenebot.geometry import planar_cam_from_world

    Rt = planar_cam_from_world(poses[:, 0], poses[:, 1], poses[:, 2])
    R, t = Rt[:, :9].reshape(-1, 3, 3), Rt[:, 9:]
    tk, ref = syn.scorers(V, F, R, t, 40, 30, backend="cpu")
    rng = np.random.default_rng(0)
    xy = np.stack([rng.uniform(-1, 1, 20), rng.uniform(-1, 1, 20)], 1)
    west = np.column_stack([xy, rng.uniform(np.pi - 0.3, np.pi + 0.3, 20)])
    east = np.column_stack([xy, rng.uniform(-0.3, 0.3, 20)])
    for scorer in (tk, ref):
        sw = scorer.score(west).score_deg
        se = scorer.score(east).score_deg
        assert np.all(se > sw)
        assert se.mean() > sw.mean() + 60.0
        assert se.mean() > 150.0  # the east wall is seen by no source at all


def test_occluded_sources_do_not_count():
    # a closed wall at x = 0 splits the room; the only source stands east of it looking west,
    # right behind the candidate's rays: without occlusion the angles would be small
    Rt_src = np.array([[1.5, 0.0, np.pi]])
    from scenebot.geometry import planar_cam_from_world

    Rt = planar_cam_from_world(Rt_src[:, 0], Rt_src[:, 1], Rt_src[:, 2])
    R, t = Rt[:, :9].reshape(-1, 3, 3), Rt[:, 9:]
    cand = np.array([[-1.0, 0.0, np.pi], [-1.5, 0.3, np.pi + 0.2]])
    Vw, Fw = syn.room(cell_m=0.5, furniture=False, wall_x=0.0)
    Vo, Fo = syn.room(cell_m=0.5, furniture=False)
    for which in ("taichi", "reference"):
        walled = syn.scorers(Vw, Fw, R, t, 40, 30, which=which)
        open_ = syn.scorers(Vo, Fo, R, t, 40, 30, which=which)
        pw = walled.score(cand, return_pixels=True).pixels
        po = open_.score(cand, return_pixels=True).pixels
        assert np.all(pw[pw >= 0] == 180.0), which
        assert np.median(po[po >= 0]) < 15.0, which  # control: the same source, no wall


def test_pixels_that_hit_nothing_are_left_out():
    # an open box (no ceiling, no wall at +x): some rays escape
    V, F = syn.room(cell_m=0.5, furniture=False)
    keep = ~((V[F][:, :, 2] > 1.99).all(axis=1) | (V[F][:, :, 0] > 2.99).all(axis=1))
    F = F[keep]
    R, t, _ = syn.ring_sources([[-1.0, 0.0]], 12)
    tk, ref = syn.scorers(V, F, R, t, 40, 30, which="both", backend="cpu")
    cand = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, np.pi]])
    for scorer in (tk, ref):
        res = scorer.score(cand, return_pixels=True)
        assert 0.2 < res.hit_fraction[0] < 0.95  # looking at the missing wall
        assert res.hit_fraction[1] > 0.99
        hit = res.pixels[0] >= 0
        np.testing.assert_allclose(res.score_deg[0], res.pixels[0][hit].mean(), rtol=1e-6)


def test_candidate_views_are_horizontal_and_right_handed():
    v = candidate_views(np.array([[1.0, 2.0, 0.3]]), syn.default_intrinsics())[0]
    R = v[:9].reshape(3, 3)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.isclose(np.linalg.det(R), 1.0)
    np.testing.assert_allclose(R[2], [np.cos(0.3), np.sin(0.3), 0.0], atol=1e-12)  # forward
    np.testing.assert_allclose(R[1], [0, 0, -1], atol=1e-12)  # image down = world down
    np.testing.assert_allclose(v[12:15], [1.0, 2.0, 0.0], atol=1e-12)


@pytest.mark.gpu
def test_gpu_matches_cpu(office):
    V, F, R, t, _ = office
    poses = random_poses(64, np.random.default_rng(5))
    cpu = syn.scorers(V, F, R, t, 80, 60, which="taichi", backend="cpu").score(poses)
    try:
        gpu_scorer = syn.scorers(V, F, R, t, 80, 60, which="taichi", backend="gpu")
    except RuntimeError:
        pytest.skip("no CUDA or Vulkan device for taichi")
    assert gpu_scorer.arch in ("cuda", "vulkan")
    gpu = gpu_scorer.score(poses)
    init_taichi("cpu")
    assert np.mean(np.abs(gpu.score_deg - cpu.score_deg)) < 0.05
    assert np.max(np.abs(gpu.score_deg - cpu.score_deg)) < 1.0


def test_gpu_rasterizer_matches_cpu_rasterizer_on_cpu(office):
    """The GPU path's rasterizer (chunks of triangles, atomic writes) runs on the CPU too."""
    import taichi as ti

    from scenebot.score import _tikernels as k

    V, F, R, t, _ = office
    tk = syn.scorers(V, F, R, t, 40, 30, which="taichi", backend="cpu")
    views = candidate_views(random_poses(16, np.random.default_rng(9)), tk.intr)
    views = np.ascontiguousarray(views, dtype=np.float32)
    out = []
    for kern in (k.raster, k.raster_per_view):
        d = ti.ndarray(ti.f32, shape=(16, 30, 40))
        k.fill(d, k.FAR)
        kern(tk._verts, tk._faces, tk._spheres, views, d, tk.near)
        out.append(d.to_numpy())
    np.testing.assert_array_equal(out[0], out[1])
    assert (out[0] < k.FAR).mean() > 0.99


def test_per_view_pass_matches_batched_passes(office):
    """The CPU pass (one thread per view: clustered rasterizer, blocks of tiles, 2x2 maxima)
    and the GPU's batched passes (run here on the CPU) give the same scores."""
    V, F, R, t, _ = office
    poses = random_poses(40, np.random.default_rng(11))  # batches of 16: the last one partial
    kw = dict(which="taichi", backend="cpu", batch_size=16)
    per_view = syn.scorers(V, F, R, t, 80, 60, **kw)
    batched = syn.scorers(V, F, R, t, 80, 60, per_view=False, **kw)
    assert per_view.per_view and not batched.per_view
    a = per_view.score(poses, return_pixels=True)
    b = batched.score(poses, return_pixels=True)
    np.testing.assert_array_equal(a.pixels >= 0, b.pixels >= 0)
    np.testing.assert_allclose(a.pixels, b.pixels, atol=0.05)
    np.testing.assert_allclose(a.score_deg, b.score_deg, atol=1e-3)
    np.testing.assert_allclose(a.hit_fraction, b.hit_fraction, atol=0)
    np.testing.assert_allclose(a.seen_fraction, b.seen_fraction, atol=1e-3)


def brute_force_pixels(tk, views, depth):
    """Pixel scores (deg) of every source, no pruning, in float64, on the scorer's own depth."""
    from scenebot.score.kernel import FAR, projection_rows

    src = tk._src_views.to_numpy()
    proj = projection_rows(src).astype(np.float64)
    D = tk.source_depth_maps().astype(np.float64)
    S, Hs, Ws = D.shape
    out = []
    for v, z in zip(np.asarray(views, np.float64), depth.astype(np.float64), strict=True):
        R, t, L = v[:9].reshape(3, 3), v[9:12], v[12:15]
        fx, fy, cx, cy = v[15:19]
        H, W = z.shape
        ii, jj = np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5)
        pc = np.stack([(ii - cx) / fx * z, (jj - cy) / fy * z, z], -1)
        P = (pc - t) @ R  # R^T (pc - t)
        r = L - P
        r /= np.linalg.norm(r, axis=-1, keepdims=True)
        best = np.full(z.shape, -2.0)
        for s in range(S):
            qz = P @ proj[s, 8:11] + proj[s, 11]
            with np.errstate(all="ignore"):
                u = (P @ proj[s, 0:3] + proj[s, 3]) / qz
                w = (P @ proj[s, 4:7] + proj[s, 7]) / qz
            ok = (qz > tk.near) & (u >= 0) & (u < Ws) & (w >= 0) & (w < Hs)
            x0 = np.clip(np.floor(np.where(ok, u, 1.0) - 0.5), 0, Ws - 1).astype(int)
            y0 = np.clip(np.floor(np.where(ok, w, 1.0) - 0.5), 0, Hs - 1).astype(int)
            x1, y1 = np.minimum(x0 + 1, Ws - 1), np.minimum(y0 + 1, Hs - 1)
            dmax = np.maximum(
                np.maximum(D[s, y0, x0], D[s, y0, x1]), np.maximum(D[s, y1, x0], D[s, y1, x1])
            )
            seen = ok & (qz <= dmax * (1.0 + tk.tol))
            d = src[s, 12:15] - P
            c = np.einsum("hwk,hwk->hw", r, d) / np.linalg.norm(d, axis=-1)
            best = np.where(seen, np.maximum(best, c), best)
        ang = np.where(best < -1.5, 180.0, np.degrees(np.arccos(np.clip(best, -1.0, 1.0))))
        out.append(np.where(z < FAR, ang, -1.0))
    return np.stack(out)


@pytest.mark.parametrize("per_view", [True, False])
def test_pruned_search_equals_every_source(office, per_view):
    """Culling, sorting and the early exit drop no source that would lower a pixel's score:
    the kernel's pixels equal the minimum over every source on the same depth."""
    V, F, R, t, _ = office
    tk = syn.scorers(V, F, R, t, 40, 30, which="taichi", backend="cpu", per_view=per_view)
    views = candidate_views(random_poses(12, np.random.default_rng(21)), tk.intr)
    pix = tk.score_views(views, return_pixels=True).pixels
    brute = brute_force_pixels(tk, views, tk.render_depth(views))
    np.testing.assert_array_equal(pix >= 0, brute >= 0)
    d = np.abs(pix - brute)
    assert np.mean(d < 0.01) > 0.999  # float32 against float64: acos near 0 is coarse
    assert d.max() < 0.1


def test_clustered_rasterizer_matches_plain_rasterizer(office):
    """The per-view rasterizer (clusters of triangles, inverse depth, no branch per pixel)
    draws the same z-buffer as the plain one, to float rounding."""
    import taichi as ti

    from scenebot.score import _tikernels as k

    V, F, R, t, _ = office
    tk = syn.scorers(V, F, R, t, 80, 60, which="taichi", backend="cpu")
    poses = random_poses(16, np.random.default_rng(9))
    poses[0] = [2.9, 1.9, 0.5]  # in a corner: triangles across the near plane
    views = np.ascontiguousarray(candidate_views(poses, tk.intr), dtype=np.float32)
    plain = ti.ndarray(ti.f32, shape=(16, 60, 80))
    k.fill(plain, k.FAR)
    k.raster_per_view(tk._verts, tk._faces, tk._spheres, views, plain, tk.near)
    plain = plain.to_numpy()
    clustered = tk.render_depth(views)
    np.testing.assert_array_equal(plain < k.FAR, clustered < k.FAR)
    hit = plain < k.FAR
    np.testing.assert_allclose(clustered[hit], plain[hit], rtol=2e-6)


def test_depth_map_maxima():
    import taichi as ti

    from scenebot.score import _tikernels as k

    init_taichi("cpu")
    d = np.random.default_rng(4).uniform(0.5, 5.0, (3, 13, 18)).astype(np.float32)
    d[0, 2:6, 3:9] = k.FAR
    src = ti.ndarray(ti.f32, shape=d.shape)
    src.from_numpy(d)
    m = ti.ndarray(ti.f32, shape=d.shape)
    k.neighbourhood_max(src, m)
    pad = np.concatenate([d, d[:, -1:]], axis=1)
    pad = np.concatenate([pad, pad[:, :, -1:]], axis=2)
    want = np.maximum(
        np.maximum(pad[:, :-1, :-1], pad[:, :-1, 1:]), np.maximum(pad[:, 1:, :-1], pad[:, 1:, 1:])
    )
    np.testing.assert_array_equal(m.to_numpy(), want)
    blk = k.DMAX_BLOCK
    mm = ti.ndarray(ti.math.vec2, shape=(3, -(-13 // blk), -(-18 // blk)))
    k.block_min_max(m, mm)
    mm = mm.to_numpy()
    for by in range(mm.shape[1]):
        for bx in range(mm.shape[2]):
            part = want[:, by * blk : (by + 1) * blk, bx * blk : (bx + 1) * blk]
            np.testing.assert_array_equal(mm[:, by, bx, 0], part.min(axis=(1, 2)))
            np.testing.assert_array_equal(mm[:, by, bx, 1], part.max(axis=(1, 2)))


def test_every_view_gets_one_task():
    import taichi as ti

    from scenebot.score import _tikernels as k

    init_taichi("cpu")

    @ti.kernel
    def count(n: ti.i32, n_tasks: ti.i32, hits: ti.types.ndarray(dtype=ti.i32, ndim=1)):
        for task in range(n_tasks):
            b = k.task_view(task, n, n_tasks)
            if b >= 0:
                ti.atomic_add(hits[b], 1)

    for n, n_tasks in [(0, 1024), (1, 1024), (7, 1024), (256, 1024), (1000, 1024), (3000, 3000)]:
        hits = np.zeros(n + 1, np.int32)
        count(n, n_tasks, hits)
        np.testing.assert_array_equal(hits, [1] * n + [0])  # each view once, none beyond
