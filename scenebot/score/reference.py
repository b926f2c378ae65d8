"""Plain numpy reference of the rendering-quality score, for tests and benchmarks.

Same definition as :mod:`scenebot.score.kernel` (read its docstring), written independently:
the primary hits and the source depth maps come from open3d's ray caster (an exact BVH ray
cast, not a rasterizer), and the angle pass is plain numpy over all pixels, source by source,
in float64.
"""

from __future__ import annotations

import numpy as np

from scenebot.geometry import Intrinsics
from scenebot.score.geometry import candidate_views
from scenebot.score.kernel import ScoreResult, summarize


def _pixel_rays(views: np.ndarray, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """World-frame rays through pixel centres, scaled so that the ray parameter is z-depth.

    Args:
        views: (N, 19) packed views (see :mod:`scenebot.score.geometry`).
        width: image width (pixels).
        height: image height (pixels).

    Returns:
        origins (N, H, W, 3) (m) and directions (N, H, W, 3) with unit camera-z component.
    """
    n = views.shape[0]
    R = views[:, :9].reshape(n, 3, 3)
    C = views[:, 12:15]
    fx, fy, cx, cy = (views[:, 15 + k][:, None, None] for k in range(4))
    ii, jj = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    dc = np.stack(
        [(ii[None] - cx) / fx, (jj[None] - cy) / fy, np.ones((n, height, width))], axis=-1
    )
    dw = np.einsum("nji,nhwj->nhwi", R, dc)  # R^T d
    org = np.broadcast_to(C[:, None, None, :], dw.shape)
    return org, dw


class ReferenceScorer:
    """Numpy/open3d implementation of the score (slow, for checking the taichi kernel).

    Args:
        verts: (V, 3) mesh vertices (m).
        faces: (F, 3) triangles.
        src_views: (S, 19) packed source views at depth-map intrinsics.
        src_size: (width, height) of the source depth maps (pixels).
        intr: candidate render intrinsics.
        depth_tolerance: relative depth tolerance of the visibility test (fraction).
        near_m: near clipping distance (m).
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
    ) -> None:
        import open3d as o3d

        self.scene = o3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(
            o3d.core.Tensor(np.asarray(verts, np.float32)),
            o3d.core.Tensor(np.asarray(faces, np.uint32)),
        )
        self.src_views = np.asarray(src_views, np.float64)
        self.src_size = src_size
        self.intr = intr
        self.tol = depth_tolerance
        self.near = near_m
        self.src_depth = self.depth(self.src_views, *src_size)

    def depth(self, views: np.ndarray, width: int, height: int) -> np.ndarray:
        """Z-depth maps (N, H, W) (m; +inf where nothing is hit) by ray casting."""
        import open3d as o3d

        org, d = _pixel_rays(views, width, height)
        # rays start on the near plane: the nearest surface beyond it, as in the rasterizer
        rays = np.concatenate([org + self.near * d, d], axis=-1).astype(np.float32)
        t = self.scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy().astype(np.float64)
        # the ray parameter is z-depth because the direction has unit camera-z component
        return np.where(np.isfinite(t), t + self.near, np.inf)

    def score(self, poses: np.ndarray, return_pixels: bool = False) -> ScoreResult:
        """Score planar candidates (N, 3) = (x m, y m, theta rad); see TaichiScorer.score."""
        views = candidate_views(np.asarray(poses, np.float64).reshape(-1, 3), self.intr)
        return self.score_views(views, return_pixels)

    def score_views(self, views: np.ndarray, return_pixels: bool = False) -> ScoreResult:
        """Score packed candidate views (N, 19)."""
        W, H = self.intr.width, self.intr.height
        pix = np.stack([self._pixels(v, W, H) for v in np.asarray(views, np.float64)])
        score, hit, seen = summarize(pix)
        return ScoreResult(score, hit, seen, pix if return_pixels else None)

    def _pixels(self, view: np.ndarray, W: int, H: int) -> np.ndarray:
        org, d = _pixel_rays(view[None], W, H)
        z = self.depth(view[None], W, H)[0].ravel()
        hit = np.isfinite(z)
        P = (org[0].reshape(-1, 3) + z[:, None] * d[0].reshape(-1, 3))[hit]  # (M, 3)
        L = view[12:15]
        r = L - P
        r /= np.linalg.norm(r, axis=1, keepdims=True)
        best = np.full(len(P), -2.0)
        Ws, Hs = self.src_size
        for s, sv in enumerate(self.src_views):
            Rs, ts, Ls = sv[:9].reshape(3, 3), sv[9:12], sv[12:15]
            q = P @ Rs.T + ts
            with np.errstate(divide="ignore", invalid="ignore"):
                u = sv[15] * q[:, 0] / q[:, 2] + sv[17]
                v = sv[16] * q[:, 1] / q[:, 2] + sv[18]
            inside = (q[:, 2] > self.near) & (u >= 0) & (v >= 0) & (u < Ws) & (v < Hs)
            x0 = np.clip(np.floor(np.where(inside, u, 0.5) - 0.5).astype(int), 0, Ws - 1)
            y0 = np.clip(np.floor(np.where(inside, v, 0.5) - 0.5).astype(int), 0, Hs - 1)
            x1, y1 = np.minimum(x0 + 1, Ws - 1), np.minimum(y0 + 1, Hs - 1)
            D = self.src_depth[s]
            dmax = np.maximum(np.maximum(D[y0, x0], D[y0, x1]), np.maximum(D[y1, x0], D[y1, x1]))
            visible = inside & (q[:, 2] <= dmax * (1.0 + self.tol))
            dv = Ls - P
            c = np.einsum("md,md->m", r, dv) / np.linalg.norm(dv, axis=1)
            best = np.where(visible, np.maximum(best, c), best)
        ang = np.where(best < -1.5, 180.0, np.degrees(np.arccos(np.clip(best, -1.0, 1.0))))
        out = np.full(H * W, -1.0)
        out[hit] = ang
        return out.reshape(H, W)
