"""Loading scenes: the built-in generators and textured mesh files (OBJ+MTL, PLY, glTF/GLB).

Scene files are in metres with z up, as a scanned room exported from most tools. Textures
come from the file's materials; a material without a texture renders in its flat colour.
"""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import numpy as np

from scenebot.scene.mesh import Material, SceneMesh

SUPPORTED_SUFFIXES = (".obj", ".ply", ".glb", ".gltf")


class SceneLoadError(ValueError):
    """A scene could not be loaded; the message names the file and what to fix."""


def _check_obj_references(path: Path) -> None:
    """Fail early, naming the file, when an OBJ's MTL or an MTL's texture is missing."""
    text = path.read_text(errors="replace")
    for mtl_name in re.findall(r"^\s*mtllib\s+(.+?)\s*$", text, flags=re.M):
        mtl = path.parent / mtl_name
        if not mtl.is_file():
            raise SceneLoadError(
                f"scene file {path}: material library {mtl} not found "
                "(keep the .mtl next to the .obj, or fix the mtllib line)"
            )
        mtl_text = mtl.read_text(errors="replace")
        pattern = r"^\s*map_Kd\s+(?:-\S+\s+\S+\s+)*(.+?)\s*$"
        for tex_name in re.findall(pattern, mtl_text, flags=re.M):
            tex = mtl.parent / tex_name
            if not tex.is_file():
                raise SceneLoadError(
                    f"scene file {path}: texture {tex} named in {mtl} (map_Kd) not found "
                    "(copy the texture images next to the .mtl or fix the map_Kd line)"
                )


def _material_texture(visual) -> tuple[np.ndarray, str]:
    """(texture image (H, W, 3) uint8, name) of a trimesh visual."""
    mat = getattr(visual, "material", None)
    name = getattr(mat, "name", None) or "material"
    img = None
    for attr in ("image", "baseColorTexture"):
        img = getattr(mat, attr, None) if mat is not None else None
        if img is not None:
            break
    if img is not None:
        arr = np.asarray(img.convert("RGB"))
        return arr, name
    color = None
    for attr in ("main_color", "diffuse", "baseColorFactor"):
        c = getattr(mat, attr, None) if mat is not None else None
        if c is not None:
            color = np.asarray(c, dtype=np.float64).ravel()[:3]
            if color.max() <= 1.0 and attr == "baseColorFactor":
                color = color * 255
            break
    if color is None:
        color = np.array([180.0, 180.0, 180.0])
    return np.clip(color, 0, 255).astype(np.uint8).reshape(1, 1, 3), name


def detect_floor_z(vertices: np.ndarray, triangles: np.ndarray) -> float:
    """Height of the floor: the lowest large upward-facing area (area-weighted mode)."""
    v = vertices[triangles]
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    area = 0.5 * np.linalg.norm(n, axis=1)
    nz = np.abs(n[:, 2]) / np.maximum(2 * area, 1e-12)
    horiz = nz > 0.9
    if not np.any(horiz):
        return float(vertices[:, 2].min())
    z = v[horiz, :, 2].mean(axis=1)
    a = area[horiz]
    lo = z.min()
    bins = np.arange(lo, lo + 0.5 + 0.02, 0.02)
    hist, edges = np.histogram(z, bins=bins, weights=a)
    if hist.sum() <= 0:
        return float(lo)
    k = int(np.argmax(hist))
    sel = (z >= edges[k]) & (z <= edges[k + 1])
    return float(np.average(z[sel], weights=a[sel]))


def load_scene_file(path: Path | str, floor_z: float | None = None) -> SceneMesh:
    """Load a textured mesh scene.

    Args:
        path: an ``.obj`` (with its ``.mtl`` and textures), ``.ply`` (with UVs and a
            ``TextureFile`` comment) or ``.glb`` / ``.gltf`` file; metres, z up.
        floor_z: floor height; ``None`` detects it from upward-facing surfaces.

    Raises:
        SceneLoadError: file missing, unreadable, unsupported, without triangles, or with a
            missing texture.
    """
    import trimesh

    path = Path(path)
    if not path.is_file():
        raise SceneLoadError(f"scene file {path} not found (check world.file in config.yaml)")
    if path.suffix.lower() not in SUPPORTED_SUFFIXES:
        raise SceneLoadError(
            f"scene file {path}: unsupported format {path.suffix!r}; "
            f"use one of {', '.join(SUPPORTED_SUFFIXES)}"
        )
    if path.suffix.lower() == ".obj":
        _check_obj_references(path)
    try:
        loaded = trimesh.load(path, force="scene", process=False)
    except Exception as exc:
        raise SceneLoadError(f"scene file {path} could not be read: {exc}") from exc
    verts, tris, uvs, mids, materials = [], [], [], [], []
    mat_index: dict[int, int] = {}
    base = 0
    geoms = loaded.dump(concatenate=False) if hasattr(loaded, "dump") else [loaded]
    for g in geoms:
        if not hasattr(g, "faces") or len(g.faces) == 0:
            continue
        visual = g.visual
        uv = getattr(visual, "uv", None)
        tex, name = _material_texture(visual)
        key = id(getattr(visual, "material", None)) if getattr(visual, "material", None) else -1
        if key not in mat_index or key == -1:
            mat_index[key] = len(materials)
            materials.append(Material(f"{name}_{len(materials)}", tex))
        mi = mat_index[key]
        faces = np.asarray(g.faces, dtype=np.int64)
        verts.append(np.asarray(g.vertices, dtype=np.float64))
        tris.append(faces + base)
        if uv is not None and len(uv) == len(g.vertices) and tex.shape[0] > 1:
            uv = np.asarray(uv, dtype=np.float64).copy()
            uv[:, 1] = 1.0 - uv[:, 1]  # files put v = 0 at the bottom of the image
            uvs.append(uv[faces])
        else:
            uvs.append(np.full((len(faces), 3, 2), 0.5))
        mids.append(np.full(len(faces), mi))
        base += len(g.vertices)
    if not tris:
        raise SceneLoadError(f"scene file {path} contains no triangles")
    v = np.concatenate(verts)
    t = np.concatenate(tris)
    fz = detect_floor_z(v, t) if floor_z is None else float(floor_z)
    lo, hi = v.min(0), v.max(0)
    ceiling = hi[2] - 0.1
    lights = [
        [lo[0] + (hi[0] - lo[0]) * a, lo[1] + (hi[1] - lo[1]) * b, ceiling]
        for a in (1 / 3, 2 / 3)
        for b in (1 / 3, 2 / 3)
    ]
    return SceneMesh(
        vertices=v,
        triangles=t,
        uvs=np.concatenate(uvs),
        material_ids=np.concatenate(mids),
        materials=materials,
        lights=np.array(lights),
        floor_z=fz,
        start=None,
        name=path.stem,
    )


# Built-in scene generators: name -> (module, function of the seed).
BUILTIN_SCENES = {
    "office": ("scenebot.scene.office", "office"),
    "flat": ("scenebot.scene.flat", "flat"),
    "rooms": ("scenebot.scene.rooms", "rooms"),
}


def load_world_scene(world_cfg) -> SceneMesh:
    """The scene a :class:`~scenebot.config.WorldConfig` names."""
    if world_cfg.file is not None:
        return load_scene_file(world_cfg.file, world_cfg.floor_z)
    if world_cfg.builtin in BUILTIN_SCENES:
        module, func = BUILTIN_SCENES[world_cfg.builtin]
        scene = getattr(importlib.import_module(module), func)(world_cfg.seed)
        if world_cfg.floor_z is not None:
            scene.floor_z = world_cfg.floor_z
        return scene
    allowed = ", ".join(repr(k) for k in BUILTIN_SCENES)
    raise SceneLoadError(f"unknown built-in scene {world_cfg.builtin!r}; allowed: {allowed}")
