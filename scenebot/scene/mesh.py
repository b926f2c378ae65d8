"""Textured triangle-mesh scenes: the world the simulator renders and collides with.

A :class:`SceneMesh` is a plain triangle soup with per-corner texture coordinates and one
material per triangle. Units are metres, z points up, the floor is at ``floor_z``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from scenebot.robot.base import Pose2D


@dataclass
class Material:
    """A surface material.

    Attributes:
        name: material name (from the scene file or the generator).
        texture: (H, W, 3) uint8 sRGB image; a 1x1 image is a flat colour.
        specular: strength of a white Blinn-Phong highlight in [0, 1] (shiny surfaces).
        shininess: Blinn-Phong exponent.
        emissive: the surface is a light source (rendered unlit at full brightness).
    """

    name: str
    texture: np.ndarray
    specular: float = 0.0
    shininess: float = 40.0
    emissive: bool = False


@dataclass
class SceneMesh:
    """A textured triangle mesh in metres, z up.

    Attributes:
        vertices: (V, 3) float64 positions.
        triangles: (T, 3) int32 vertex indices.
        uvs: (T, 3, 2) float32 texture coordinates per triangle corner (repeat wrap;
            v = 0 is the top row of the texture image).
        material_ids: (T,) int32 index into ``materials``.
        materials: the materials.
        lights: (L, 3) point-light positions (m).
        floor_z: height of the floor (m).
        start: default start pose of the robot, or ``None``.
        name: scene name.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    uvs: np.ndarray
    material_ids: np.ndarray
    materials: list[Material]
    lights: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    floor_z: float = 0.0
    start: Pose2D | None = None
    name: str = "scene"

    def __post_init__(self) -> None:
        self.vertices = np.asarray(self.vertices, dtype=np.float64).reshape(-1, 3)
        self.triangles = np.asarray(self.triangles, dtype=np.int32).reshape(-1, 3)
        self.uvs = np.asarray(self.uvs, dtype=np.float32).reshape(-1, 3, 2)
        self.material_ids = np.asarray(self.material_ids, dtype=np.int32).reshape(-1)
        self.lights = np.asarray(self.lights, dtype=np.float64).reshape(-1, 3)
        n = len(self.triangles)
        if len(self.uvs) != n or len(self.material_ids) != n:
            raise ValueError(
                f"scene {self.name!r}: {n} triangles but {len(self.uvs)} uv triples and "
                f"{len(self.material_ids)} material ids"
            )

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(min, max) corners of the axis-aligned bounding box, each (3,)."""
        return self.vertices.min(axis=0), self.vertices.max(axis=0)

    def texel_size_m(self) -> np.ndarray:
        """(T,) approximate size of one texel on each triangle, in metres.

        Used to pick the mip level when rendering (texture antialiasing): the ratio of the
        triangle's area in metres to its area in texels.
        """
        v = self.vertices[self.triangles]
        area_m = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
        sizes = np.array([m.texture.shape[:2] for m in self.materials], dtype=np.float64)
        hw = sizes[self.material_ids]
        uv = self.uvs.astype(np.float64)
        duv1 = (uv[:, 1] - uv[:, 0]) * hw[:, ::-1]
        duv2 = (uv[:, 2] - uv[:, 0]) * hw[:, ::-1]
        area_tex = 0.5 * np.abs(duv1[:, 0] * duv2[:, 1] - duv1[:, 1] * duv2[:, 0])
        with np.errstate(divide="ignore", invalid="ignore"):
            size = np.sqrt(area_m / area_tex)
        return np.where(np.isfinite(size) & (area_tex > 1e-12), size, 1.0)

    def to_open3d_legacy(self):
        """An ``open3d.geometry.TriangleMesh`` of the geometry (no textures)."""
        import open3d as o3d

        mesh = o3d.geometry.TriangleMesh(
            o3d.utility.Vector3dVector(self.vertices),
            o3d.utility.Vector3iVector(self.triangles),
        )
        return mesh


class SceneBuilder:
    """Accumulates quads and boxes into a :class:`SceneMesh`."""

    def __init__(self, name: str):
        self.name = name
        self._verts: list[np.ndarray] = []
        self._tris: list[np.ndarray] = []
        self._uvs: list[np.ndarray] = []
        self._mids: list[np.ndarray] = []
        self._n = 0
        self.materials: list[Material] = []
        self._mat_index: dict[str, int] = {}
        self.lights: list[np.ndarray] = []

    def material(self, mat: Material) -> int:
        """Register a material (once per name) and return its index."""
        if mat.name not in self._mat_index:
            self._mat_index[mat.name] = len(self.materials)
            self.materials.append(mat)
        return self._mat_index[mat.name]

    def quad(
        self,
        origin,
        u_vec,
        v_vec,
        material: int,
        uv_size: tuple[float, float] | None = None,
        uv_offset: tuple[float, float] = (0.0, 0.0),
    ) -> None:
        """Add the parallelogram ``origin + a u_vec + b v_vec``, a, b in [0, 1].

        The texture's u axis runs along ``u_vec`` and its v axis along ``v_vec`` (v = 0 at
        ``origin + v_vec``, so images appear upright when ``v_vec`` points up). With
        ``uv_size = (su, sv)`` the texture repeats every ``su`` x ``sv`` metres; without it
        the texture is stretched once over the quad. The front face is the side
        ``u_vec x v_vec`` points to (both sides render).
        """
        o = np.asarray(origin, dtype=np.float64)
        u = np.asarray(u_vec, dtype=np.float64)
        v = np.asarray(v_vec, dtype=np.float64)
        corners = np.array([o, o + u, o + u + v, o + v])
        if uv_size is None:
            su, sv = 1.0, 1.0
        else:
            su = np.linalg.norm(u) / uv_size[0]
            sv = np.linalg.norm(v) / uv_size[1]
        ou, ov = uv_offset
        # v = 0 at the top edge (origin + v_vec), so images appear upright
        uv = np.array([[ou, ov + sv], [ou + su, ov + sv], [ou + su, ov], [ou, ov]])
        b = self._n
        self._verts.append(corners)
        self._tris.append(np.array([[b, b + 1, b + 2], [b, b + 2, b + 3]]))
        self._uvs.append(np.array([uv[[0, 1, 2]], uv[[0, 2, 3]]]))
        self._mids.append(np.array([material, material]))
        self._n += 4

    def box(
        self,
        lo,
        hi,
        materials: int | dict[str, int],
        uv_size: tuple[float, float] | None = (1.0, 1.0),
        skip: tuple[str, ...] = (),
    ) -> None:
        """Add an axis-aligned box ``lo``-``hi`` (each (3,)).

        ``materials`` is one material for all faces or a dict with keys among
        ``top, bottom, xneg, xpos, yneg, ypos`` and ``side`` (default for the four sides).
        Faces named in ``skip`` are left out.
        """
        lo = np.asarray(lo, dtype=np.float64)
        hi = np.asarray(hi, dtype=np.float64)
        d = hi - lo
        ex, ey, ez = np.array([d[0], 0, 0]), np.array([0, d[1], 0]), np.array([0, 0, d[2]])

        def mat(face: str) -> int:
            if isinstance(materials, int):
                return materials
            return materials.get(face, materials.get("side", next(iter(materials.values()))))

        faces = {
            "yneg": (lo, ex, ez),
            "xpos": (lo + ex, ey, ez),
            "ypos": (lo + ex + ey, -ex, ez),
            "xneg": (lo + ey, -ey, ez),
            "top": (lo + ez, ex, ey),
            "bottom": (lo + ey, ex, -ey),
        }
        for name, (o, u, v) in faces.items():
            if name in skip:
                continue
            self.quad(o, u, v, mat(name), uv_size=uv_size)

    def prism(self, center_xy, radius, z0, z1, sides, material, cap_material=None) -> None:
        """Add a vertical regular prism (a cylinder approximation) with a top cap."""
        cx, cy = center_xy
        ang = np.linspace(0, 2 * np.pi, sides + 1)
        circumference = 2 * np.pi * radius
        for k in range(sides):
            p0 = np.array([cx + radius * np.cos(ang[k]), cy + radius * np.sin(ang[k]), z0])
            p1 = np.array([cx + radius * np.cos(ang[k + 1]), cy + radius * np.sin(ang[k + 1]), z0])
            self.quad(
                p0,
                p1 - p0,
                [0, 0, z1 - z0],
                material,
                uv_size=(circumference, z1 - z0),
                uv_offset=(k / sides, 0.0),
            )
        cap = material if cap_material is None else cap_material
        for k in range(sides):
            b = self._n
            pts = np.array(
                [
                    [cx, cy, z1],
                    [cx + radius * np.cos(ang[k]), cy + radius * np.sin(ang[k]), z1],
                    [cx + radius * np.cos(ang[k + 1]), cy + radius * np.sin(ang[k + 1]), z1],
                ]
            )
            self._verts.append(pts)
            self._tris.append(np.array([[b, b + 1, b + 2]]))
            uv = 0.5 + (pts[:, :2] - [cx, cy]) / (2 * radius)
            self._uvs.append(uv[None].astype(np.float64))
            self._mids.append(np.array([cap]))
            self._n += 3

    def light(self, pos) -> None:
        self.lights.append(np.asarray(pos, dtype=np.float64))

    def build(self, floor_z: float = 0.0, start: Pose2D | None = None) -> SceneMesh:
        return SceneMesh(
            vertices=np.concatenate(self._verts),
            triangles=np.concatenate(self._tris),
            uvs=np.concatenate(self._uvs),
            material_ids=np.concatenate(self._mids),
            materials=self.materials,
            lights=np.array(self.lights).reshape(-1, 3),
            floor_z=floor_z,
            start=start,
            name=self.name,
        )
