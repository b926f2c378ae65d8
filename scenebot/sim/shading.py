"""The simulator's shading of ray hits in one taichi kernel (per hit, in parallel).

What :class:`scenebot.sim.renderer.Renderer` computes for every pixel that hit the scene:
the texture coordinates at the hit, the mip level from the pixel's footprint, a bilinear
texture lookup in that level, Lambertian light from every point light plus ambient, a
Blinn-Phong highlight on shiny materials, emissive materials unlit. The numpy version of the
same arithmetic (:func:`shade_reference`, float64) was the renderer's until 2026-11-27; it
stays as the reference the tests hold the kernel to (photos within a grey level, a few
pixels at a mip level's rounding boundary apart) and took 70 % of a photo's time, on one
core (0.33 of 0.48 s at 640x480).

The kernel runs where taichi runs in the process (:func:`scenebot.taichi_setup.init_taichi`;
the capture stage starts it on the CPU, so that a photo is the same on every machine).
"""

# no `from __future__ import annotations`: taichi reads the kernel's annotations as objects
from functools import cache

import numpy as np


@cache
def _kernel():
    """The taichi kernel (built on first use: importing the renderer starts no taichi)."""
    import taichi as ti

    nd = ti.types.ndarray

    @ti.kernel
    def shade(
        prim: nd(dtype=ti.i32, ndim=1),
        t_hit: nd(dtype=ti.f32, ndim=1),
        bary: nd(dtype=ti.f32, ndim=2),
        dirs: nd(dtype=ti.f32, ndim=2),
        origin: nd(dtype=ti.f32, ndim=1),
        pixel_angle: ti.f32,
        tri_mat: nd(dtype=ti.i32, ndim=1),
        tri_uv: nd(dtype=ti.f32, ndim=3),
        tri_n: nd(dtype=ti.f32, ndim=2),
        texel: nd(dtype=ti.f32, ndim=1),
        n_levels: nd(dtype=ti.i32, ndim=1),
        lw: nd(dtype=ti.i32, ndim=2),
        lh: nd(dtype=ti.i32, ndim=2),
        loff: nd(dtype=ti.i32, ndim=2),
        texels: nd(dtype=ti.f32, ndim=2),
        lights: nd(dtype=ti.f32, ndim=2),
        ambient: ti.f32,
        light_power: ti.f32,
        spec: nd(dtype=ti.f32, ndim=1),
        shin: nd(dtype=ti.f32, ndim=1),
        emissive: nd(dtype=ti.i32, ndim=1),
        out: nd(dtype=ti.f32, ndim=2),
    ):
        for i in prim:
            f = prim[i]
            if f < 0:
                for c in ti.static(range(3)):
                    out[i, c] = 0.0
                continue
            t = t_hit[i]
            d = ti.Vector([dirs[i, 0], dirs[i, 1], dirs[i, 2]])
            p = ti.Vector([origin[0], origin[1], origin[2]]) + d * t
            m = tri_mat[f]
            bu, bv = bary[i, 0], bary[i, 1]
            u = (1.0 - bu - bv) * tri_uv[f, 0, 0] + bu * tri_uv[f, 1, 0] + bv * tri_uv[f, 2, 0]
            v = (1.0 - bu - bv) * tri_uv[f, 0, 1] + bu * tri_uv[f, 1, 1] + bv * tri_uv[f, 2, 1]
            nrm = ti.Vector([tri_n[f, 0], tri_n[f, 1], tri_n[f, 2]])
            cos_i = nrm.dot(d)
            if cos_i > 0:
                nrm = -nrm
            cos_i = ti.abs(cos_i)
            footprint = t * pixel_angle / ti.max(cos_i, 0.2)
            lod = ti.log(ti.max(footprint / texel[f], 1.0)) / ti.log(2.0)
            lvl = ti.min(ti.cast(ti.round(lod), ti.i32), n_levels[m] - 1)
            w, h, off = lw[m, lvl], lh[m, lvl], loff[m, lvl]
            x = u * w - 0.5
            y = v * h - 0.5
            x0f, y0f = ti.floor(x), ti.floor(y)
            fx, fy = x - x0f, y - y0f
            x0 = ti.cast(x0f, ti.i32) % w
            y0 = ti.cast(y0f, ti.i32) % h
            x1 = (x0 + 1) % w
            y1 = (y0 + 1) % h
            r0, r1 = off + y0 * w, off + y1 * w
            albedo = ti.Vector([0.0, 0.0, 0.0])
            for c in ti.static(range(3)):
                a, b = texels[r0 + x0, c], texels[r0 + x1, c]
                top = a + (b - a) * fx
                a, b = texels[r1 + x0, c], texels[r1 + x1, c]
                bot = a + (b - a) * fx
                albedo[c] = top + (bot - top) * fy
            light = ambient
            sp = 0.0
            ks = spec[m]
            for k in range(lights.shape[0]):
                to_l = ti.Vector([lights[k, 0], lights[k, 1], lights[k, 2]]) - p
                dist2 = to_l.dot(to_l)
                inv = 1.0 / ti.sqrt(dist2)
                ndl = ti.max(nrm.dot(to_l) * inv, 0.0)
                light += light_power * ndl / (1.0 + 0.08 * dist2)
                if ks > 0 and ndl > 0:
                    half = (to_l * inv - d).normalized()
                    sp += ks * ti.max(nrm.dot(half), 0.0) ** shin[m]
            col = albedo * light + 255.0 * ti.min(sp, 1.5)
            if emissive[m] != 0:
                col = albedo
            for c in ti.static(range(3)):
                out[i, c] = col[c]

    return shade


class SceneShading:
    """The scene's arrays as the kernel reads them (made once per renderer).

    Args:
        triangles_material: (T,) material index per triangle.
        triangle_uvs: (T, 3, 2) texture coordinates of the corners.
        normals: (T, 3) unit face normals.
        texel_m: (T,) texel size (m) of each triangle's texture.
        atlas: the mip pyramids (``n_levels``, ``w``, ``h``, ``off``, ``texels``).
        lights: (L, 3) point lights (m).
        specular, shininess: (M,) per material; emissive: (M,) bool.
    """

    def __init__(self, triangles_material, triangle_uvs, normals, texel_m, atlas, lights,
                 specular, shininess, emissive):  # fmt: skip
        f32, i32 = np.float32, np.int32
        self.tri_mat = np.ascontiguousarray(triangles_material, i32)
        self.tri_uv = np.ascontiguousarray(triangle_uvs, f32)
        self.tri_n = np.ascontiguousarray(normals, f32)
        self.texel = np.ascontiguousarray(texel_m, f32)
        if len(atlas.texels) >= 2**31:
            raise ValueError(f"texture atlas of {len(atlas.texels)} texels: too large (2^31)")
        self.n_levels = np.ascontiguousarray(atlas.n_levels, i32)
        self.lw = np.ascontiguousarray(atlas.w, i32)
        self.lh = np.ascontiguousarray(atlas.h, i32)
        self.loff = np.ascontiguousarray(atlas.off, i32)
        self.texels = np.ascontiguousarray(atlas.texels, f32)
        self.lights = np.ascontiguousarray(np.reshape(lights, (-1, 3)), f32)
        self.spec = np.ascontiguousarray(specular, f32)
        self.shin = np.ascontiguousarray(shininess, f32)
        self.emissive = np.ascontiguousarray(emissive, i32)

    def shade(self, origin: np.ndarray, dirs: np.ndarray, hit: dict, pixel_angle: float,
              ambient: float, light_power: float) -> np.ndarray:  # fmt: skip
        """Colours (N, 3) float32 in 0..255 of the hits ``hit`` (:meth:`Renderer.cast`) of
        the rays from ``origin`` (3,) along ``dirs`` (N, 3); black where nothing was hit."""
        from scenebot.taichi_setup import init_taichi

        init_taichi("cpu", -1)  # started already (another stage of the process): as it is
        n = len(dirs)
        out = np.zeros((n, 3), np.float32)
        if n == 0:
            return out
        _kernel()(
            np.ascontiguousarray(hit["prim"], np.int32),
            np.ascontiguousarray(np.where(np.isfinite(hit["t"]), hit["t"], 0.0), np.float32),
            np.ascontiguousarray(hit["bary"], np.float32),
            np.ascontiguousarray(dirs, np.float32),
            np.ascontiguousarray(origin, np.float32).reshape(3),
            float(pixel_angle), self.tri_mat, self.tri_uv, self.tri_n, self.texel,
            self.n_levels, self.lw, self.lh, self.loff, self.texels, self.lights,
            float(ambient), float(light_power), self.spec, self.shin, self.emissive, out,
        )  # fmt: skip
        return out
