"""CPU pinhole-camera renderer of textured scenes (open3d ray casting, Embree-backed).

Shading: albedo from mip-mapped, trilinearly filtered textures (texture antialiasing),
Lambertian lighting from the scene's point lights plus ambient, a Blinn-Phong highlight on
shiny materials (view-dependent, as a real office's whiteboards and metal are), emissive
materials unlit (one taichi kernel per photo, :mod:`scenebot.sim.shading`), and mild sensor
noise. Geometric edges are antialiased by re-casting four
sub-pixel rays at pixels whose neighbours differ in depth or surface.

Camera axes follow OpenCV/COLMAP: x right, y down, z forward; a pose is ``R_cam_from_world``
(3, 3) and the centre (3,) in world coordinates. Pixel (i, j) has its centre at
``(j + 0.5, i + 0.5)`` in the image plane, like COLMAP. The camera model
(:class:`~scenebot.geometry.Intrinsics`, :func:`~scenebot.geometry.look_rotation`) is
:mod:`scenebot.geometry`'s.
"""

from __future__ import annotations

import cv2
import numpy as np

from scenebot.geometry import Intrinsics
from scenebot.geometry import look_rotation as look_rotation  # re-exported (tests, benchmarks)
from scenebot.scene.mesh import SceneMesh


class _TextureAtlas:
    """All materials' mip pyramids in one flat array, sampled trilinearly in numpy."""

    def __init__(self, scene: SceneMesh):
        mats = scene.materials
        levels: list[list[np.ndarray]] = []
        for m in mats:
            img = m.texture.astype(np.float32)
            pyr = [img]
            while min(pyr[-1].shape[:2]) > 1:
                h, w = pyr[-1].shape[:2]
                pyr.append(cv2.resize(pyr[-1], (max(1, w // 2), max(1, h // 2)), cv2.INTER_AREA))
                if pyr[-1].ndim == 2:
                    pyr[-1] = pyr[-1][..., None]
            levels.append(pyr)
        nl = max(len(p) for p in levels)
        self.n_levels = np.array([len(p) for p in levels], np.int32)
        self.w = np.ones((len(mats), nl), np.int64)
        self.h = np.ones((len(mats), nl), np.int64)
        self.off = np.zeros((len(mats), nl), np.int64)
        chunks, off = [], 0
        for i, pyr in enumerate(levels):
            for k in range(nl):
                img = pyr[min(k, len(pyr) - 1)]
                self.h[i, k], self.w[i, k] = img.shape[:2]
                self.off[i, k] = off
                if k < len(pyr):
                    chunks.append(img.reshape(-1, 3))
                    off += img.shape[0] * img.shape[1]
                else:
                    self.off[i, k] = self.off[i, len(pyr) - 1]
        self.texels = np.ascontiguousarray(np.concatenate(chunks), dtype=np.float32)

    def _bilinear(self, m: np.ndarray, lvl: np.ndarray, uv: np.ndarray) -> np.ndarray:
        w, h, off = self.w[m, lvl], self.h[m, lvl], self.off[m, lvl]
        x = uv[:, 0] * w - 0.5
        y = uv[:, 1] * h - 0.5
        x0f, y0f = np.floor(x), np.floor(y)
        fx = (x - x0f).astype(np.float32)[:, None]
        fy = (y - y0f).astype(np.float32)[:, None]
        x0 = x0f.astype(np.int64) % w
        y0 = y0f.astype(np.int64) % h
        x1 = x0 + 1
        x1[x1 == w] = 0
        y1 = y0 + 1
        y1[y1 == h] = 0
        r0 = off + y0 * w
        r1 = off + y1 * w
        t = self.texels
        a, b = t[r0 + x0], t[r0 + x1]  # four gathers (each texel row once)
        top = a + (b - a) * fx
        a, b = t[r1 + x0], t[r1 + x1]
        bot = a + (b - a) * fx
        return top + (bot - top) * fy

    def sample(self, m: np.ndarray, uv: np.ndarray, lod: np.ndarray) -> np.ndarray:
        """Bilinear lookup in the nearest mip level.

        Args:
            m: (N,) material index.
            uv: (N, 2) texture coordinates.
            lod: (N,) mip level (float; rounded to the nearest level).

        Returns:
            (N, 3) float32 colours (0..255).
        """
        top = self.n_levels[m] - 1
        lvl = np.minimum(np.rint(np.maximum(lod, 0.0)).astype(np.int64), top)
        return self._bilinear(m, lvl, uv)


class Renderer:
    """Renders photos, depth maps and single rays of a :class:`SceneMesh`.

    Args:
        scene: the scene.
        ambient: ambient light level (fraction of albedo).
        light_power: brightness of each point light at 1 m.
        noise_sigma: sensor noise (8-bit levels, Gaussian).
        antialias: re-cast 4 sub-pixel rays at geometric edges.
    """

    def __init__(
        self,
        scene: SceneMesh,
        ambient: float = 0.42,
        light_power: float = 0.55,
        noise_sigma: float = 1.5,
        antialias: bool = True,
    ):
        import open3d as o3d

        self.scene = scene
        self.ambient = ambient
        self.light_power = light_power
        self.noise_sigma = noise_sigma
        self.antialias = antialias
        self._rc = o3d.t.geometry.RaycastingScene()
        self._rc.add_triangles(
            o3d.core.Tensor(scene.vertices.astype(np.float32)),
            o3d.core.Tensor(scene.triangles.astype(np.uint32)),
        )
        v = scene.vertices[scene.triangles]
        n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        self._normals = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
        self._texel = scene.texel_size_m()
        self._atlas = _TextureAtlas(scene)
        self._spec = np.array([m.specular for m in scene.materials], np.float64)
        self._shin = np.array([m.shininess for m in scene.materials], np.float64)
        self._emissive = np.array([m.emissive for m in scene.materials], bool)
        self._ray_cache: dict[tuple, np.ndarray] = {}
        self._shading = None  # the taichi kernel's arrays, made on the first photo

    # ----------------------------------------------------------------- ray casting
    def cast(self, origins: np.ndarray, dirs: np.ndarray) -> dict[str, np.ndarray]:
        """Cast rays. origins, dirs: (N, 3), dirs unit length.

        Returns:
            dict with ``t`` (N,) distance (inf on miss), ``prim`` (N,) triangle id
            (-1 on miss), ``bary`` (N, 2) barycentric (u, v) of the hit.
        """
        import open3d as o3d

        rays = np.concatenate([origins, dirs], axis=1).astype(np.float32)
        ans = self._rc.cast_rays(o3d.core.Tensor(rays))
        t = ans["t_hit"].numpy().astype(np.float64)
        prim = ans["primitive_ids"].numpy().astype(np.int64)
        prim[~np.isfinite(t)] = -1
        prim[prim >= len(self.scene.triangles)] = -1
        return {"t": t, "prim": prim, "bary": ans["primitive_uvs"].numpy().astype(np.float64)}

    def _shade(self, origins, dirs, hit, pixel_angle: float) -> np.ndarray:
        """Colours (N, 3) float32 in 0..255 of the hits of rays ``origins + t dirs`` (the
        rays of one camera: ``origins`` all its centre), by the taichi kernel of
        :mod:`scenebot.sim.shading`."""
        if self._shading is None:
            from scenebot.sim.shading import SceneShading

            self._shading = SceneShading(
                self.scene.material_ids, self.scene.uvs, self._normals, self._texel,
                self._atlas, self.scene.lights, self._spec, self._shin, self._emissive,
            )  # fmt: skip
        origin = np.asarray(origins, float)[0] if len(dirs) else np.zeros(3)  # no copy
        return self._shading.shade(origin, dirs, hit, pixel_angle, self.ambient, self.light_power)

    def shade_reference(self, origins, dirs, hit, pixel_angle: float) -> np.ndarray:
        """:meth:`_shade` in numpy, float64 (the renderer's own until 2026-11-27): the
        reference the tests hold the kernel to."""
        n_rays = len(dirs)
        out = np.zeros((n_rays, 3))
        ok = hit["prim"] >= 0
        if not np.any(ok):
            return out
        prim = hit["prim"][ok]
        t = hit["t"][ok]
        d = dirs[ok]
        p = origins[ok] + d * t[:, None]
        mids = self.scene.material_ids[prim]
        bu, bv = hit["bary"][ok, 0:1], hit["bary"][ok, 1:2]
        uvs = self.scene.uvs[prim].astype(np.float64)
        uv = (1 - bu - bv) * uvs[:, 0] + bu * uvs[:, 1] + bv * uvs[:, 2]
        nrm = self._normals[prim]
        cos_i = np.einsum("ij,ij->i", nrm, d)
        nrm = np.where(cos_i[:, None] > 0, -nrm, nrm).astype(np.float32)
        cos_i = np.abs(cos_i)
        footprint = t * pixel_angle / np.maximum(cos_i, 0.2)
        lod = np.log2(np.maximum(footprint / self._texel[prim], 1.0))
        albedo = self._atlas.sample(mids, uv, lod)
        p32 = p.astype(np.float32)
        d32 = d.astype(np.float32)
        light = np.full(len(p), self.ambient, np.float32)
        spec = np.zeros(len(p), np.float32)
        ks = self._spec[mids]
        shiny = np.nonzero(ks > 0)[0]
        for lp in self.scene.lights.astype(np.float32):
            to_l = lp - p32
            dist2 = np.einsum("ij,ij->i", to_l, to_l)
            inv = 1.0 / np.sqrt(dist2)
            ndl = np.maximum(np.einsum("ij,ij->i", nrm, to_l) * inv, 0.0)
            light += self.light_power * ndl / (1.0 + 0.08 * dist2)
            if len(shiny):
                half = to_l[shiny] * inv[shiny, None] - d32[shiny]
                half /= np.sqrt(np.einsum("ij,ij->i", half, half))[:, None]
                ndh = np.maximum(np.einsum("ij,ij->i", nrm[shiny], half), 0.0)
                spec[shiny] += (
                    ks[shiny] * ndh ** self._shin[mids[shiny]] * (ndl[shiny] > 0)
                ).astype(np.float32)
        col = albedo * light[:, None] + 255.0 * np.minimum(spec, 1.5)[:, None]
        em = self._emissive[mids]
        col[em] = albedo[em]
        out[ok] = col
        return out

    # ------------------------------------------------------------------- images
    def _pixel_rays(self, intr: Intrinsics, R: np.ndarray, offsets=(0.5, 0.5), pix=None):
        if pix is None:  # every pixel: the camera-frame rays depend on the intrinsics only
            key = (intr.width, intr.height, intr.fx, intr.fy, intr.cx, intr.cy, *offsets)
            d_cam = self._ray_cache.get(key)
            if d_cam is None:
                jj, ii = np.meshgrid(np.arange(intr.width), np.arange(intr.height))
                d_cam = self._camera_rays(intr, offsets, ii.ravel(), jj.ravel())
                self._ray_cache = {key: d_cam}  # one camera at a time
        else:
            d_cam = self._camera_rays(intr, offsets, *pix)
        return d_cam @ R  # world = R^T d_cam (row vectors)

    @staticmethod
    def _camera_rays(intr: Intrinsics, offsets, ii: np.ndarray, jj: np.ndarray) -> np.ndarray:
        x = (jj + offsets[0] - intr.cx) / intr.fx
        y = (ii + offsets[1] - intr.cy) / intr.fy
        d_cam = np.stack([x, y, np.ones_like(x)], axis=1)
        d_cam /= np.linalg.norm(d_cam, axis=1, keepdims=True)
        return d_cam

    def render(
        self,
        intr: Intrinsics,
        R_cam_from_world: np.ndarray,
        center: np.ndarray,
        rng: np.random.Generator | None = None,
        return_depth: bool = False,
    ):
        """Render a photo.

        Args:
            intr: intrinsics.
            R_cam_from_world: (3, 3) rotation.
            center: (3,) camera centre in world coordinates (m).
            rng: generator for the sensor noise (no noise when ``None``).
            return_depth: also return the z-depth map.

        Returns:
            (H, W, 3) uint8 RGB image, and with ``return_depth`` the (H, W) float32 z-depth
            in metres (``inf`` where the ray hits nothing).
        """
        R = np.asarray(R_cam_from_world, np.float64)
        c = np.asarray(center, np.float64)
        dirs = self._pixel_rays(intr, R)
        origins = np.broadcast_to(c, dirs.shape)
        hit = self.cast(origins, dirs)
        pixel_angle = 1.0 / intr.fx
        col = self._shade(origins, dirs, hit, pixel_angle)
        H, W = intr.height, intr.width
        if self.antialias:
            col = self._antialias(intr, R, c, hit, col, pixel_angle)
        img = col.reshape(H, W, 3)
        if rng is not None and self.noise_sigma > 0:
            img = img + rng.normal(0.0, self.noise_sigma, img.shape)
        img8 = np.clip(img + 0.5, 0, 255).astype(np.uint8)
        if not return_depth:
            return img8
        zdir = R[2]
        depth = (hit["t"] * (dirs @ zdir)).reshape(H, W).astype(np.float32)
        return img8, depth

    def _antialias(self, intr, R, c, hit, col, pixel_angle):
        H, W = intr.height, intr.width
        t = hit["t"].reshape(H, W)
        prim = hit["prim"].reshape(H, W)
        mid = np.where(prim >= 0, self.scene.material_ids[np.maximum(prim, 0)], -1)
        tt = np.where(np.isfinite(t), t, 1e3)
        edge = np.zeros((H, W), bool)
        for axis in (0, 1):
            dt = np.abs(np.diff(tt, axis=axis)) / np.minimum(
                np.delete(tt, 0, axis), np.delete(tt, -1, axis)
            )
            diff = (dt > 0.02) | (np.diff(mid, axis=axis) != 0)
            if axis == 0:
                edge[1:] |= diff
                edge[:-1] |= diff
            else:
                edge[:, 1:] |= diff
                edge[:, :-1] |= diff
        ii, jj = np.nonzero(edge)
        if len(ii) == 0:
            return col
        acc = np.zeros((len(ii), 3), np.float32)
        for ox, oy in ((0.375, 0.125), (0.875, 0.375), (0.625, 0.875), (0.125, 0.625)):
            d = self._pixel_rays(intr, R, (ox, oy), (ii, jj))
            o = np.broadcast_to(c, d.shape)
            acc += self._shade(o, d, self.cast(o, d), pixel_angle)
        col = col.copy()
        col[ii * W + jj] = acc / 4.0
        return col

    def depth(self, intr: Intrinsics, R_cam_from_world: np.ndarray, center: np.ndarray):
        """(H, W) float32 z-depth in metres of the scene seen from a camera (inf = miss)."""
        R = np.asarray(R_cam_from_world, np.float64)
        dirs = self._pixel_rays(intr, R)
        hit = self.cast(np.broadcast_to(np.asarray(center, float), dirs.shape), dirs)
        return (hit["t"] * (dirs @ R[2])).reshape(intr.height, intr.width).astype(np.float32)
