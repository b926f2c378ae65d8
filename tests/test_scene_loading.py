"""Loading textured mesh scenes from OBJ+MTL, PLY with UVs and GLB."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from PIL import Image

from scenebot.scene.loader import SceneLoadError, detect_floor_z, load_scene_file
from scenebot.sim.renderer import Intrinsics, Renderer, look_rotation


def textured_room(floor_z: float = 0.0) -> trimesh.Trimesh:
    """A 3 x 3 x 2 m box room (inward faces) with a checkerboard texture."""
    box = trimesh.creation.box(extents=(3.0, 3.0, 2.0))
    box.invert()  # faces point into the room
    box.apply_translation([1.5, 1.5, 1.0 + floor_z])
    rng = np.random.default_rng(0)
    img = rng.integers(0, 255, (64, 64, 3), dtype=np.uint8)
    uv = box.vertices[:, :2] / 3.0  # planar map, enough for a test
    box.visual = trimesh.visual.TextureVisuals(uv=uv, image=Image.fromarray(img))
    return box


@pytest.mark.parametrize("suffix", [".obj", ".ply", ".glb"])
def test_textured_scene_files_load_and_render(tmp_path, suffix):
    path = tmp_path / f"room{suffix}"
    textured_room(floor_z=0.25).export(path)
    scene = load_scene_file(path)
    assert len(scene.triangles) == 12
    assert scene.floor_z == pytest.approx(0.25, abs=1e-6)
    assert scene.materials[0].texture.shape[0] > 1  # the texture came along
    r = Renderer(scene, noise_sigma=0)
    img = r.render(Intrinsics.from_hfov(64, 48, 60), look_rotation(0.0), [1.5, 1.5, 0.6])
    assert img.std() > 10  # textured, not a flat colour


def test_missing_file_is_named(tmp_path):
    with pytest.raises(SceneLoadError, match=r"nothere\.glb not found.*world\.file"):
        load_scene_file(tmp_path / "nothere.glb")


def test_unsupported_format_is_named(tmp_path):
    p = tmp_path / "room.stl"
    p.write_text("solid x\nendsolid x\n")
    with pytest.raises(SceneLoadError, match=r"unsupported format '.stl'"):
        load_scene_file(p)


def test_unreadable_file_is_named(tmp_path):
    p = tmp_path / "broken.glb"
    p.write_bytes(b"this is not a glb file")
    with pytest.raises(SceneLoadError, match=r"broken.glb"):
        load_scene_file(p)


def test_missing_texture_of_an_obj_is_named(tmp_path):
    path = tmp_path / "room.obj"
    textured_room().export(path)
    mtl = next(tmp_path.glob("*.mtl"))
    textures = [p for p in tmp_path.iterdir() if p.suffix in (".png", ".jpg")]
    assert textures
    for t in textures:
        t.unlink()
    with pytest.raises(SceneLoadError, match=rf"texture .* named in .*{mtl.name}"):
        load_scene_file(path)


def test_floor_detection_ignores_furniture_tops():
    room = textured_room()
    table = trimesh.creation.box(extents=(1.0, 1.0, 0.05))
    table.apply_translation([1.5, 1.5, 0.75])
    both = trimesh.util.concatenate([room, table])
    assert detect_floor_z(both.vertices, both.faces) == pytest.approx(0.0, abs=1e-6)
