"""The renderer: projection geometry, depth, antialiasing, JPEG with EXIF focal."""

from __future__ import annotations

import math

import numpy as np
import pytest
from PIL import Image

from scenebot.geometry import Intrinsics, look_rotation
from scenebot.jpeg import exif_focal_px, write_jpeg
from scenebot.scene import textures as tx
from scenebot.scene.mesh import Material, SceneBuilder
from scenebot.sim.renderer import Renderer


def marker_scene(point):
    """A grey wall at x = 5 with a small red square centred on ``point``."""
    b = SceneBuilder("marker")
    grey = b.material(Material("grey", tx.flat((128, 128, 128)), emissive=True))
    red = b.material(Material("red", tx.flat((255, 0, 0)), emissive=True))
    b.quad([5, -5, -5], [0, 10, 0], [0, 0, 10], grey)
    x, y, z = point
    b.quad([x - 0.001, y - 0.05, z - 0.05], [0, 0.1, 0], [0, 0, 0.1], red)
    return b.build()


def test_a_known_point_projects_to_the_expected_pixel():
    point = np.array([4.999, 0.7, 1.3])
    r = Renderer(marker_scene(point), noise_sigma=0, antialias=True)
    intr = Intrinsics.from_hfov(320, 240, 60)
    R = look_rotation(math.radians(10), math.radians(5))
    c = np.array([0.2, -0.1, 1.0])
    img = r.render(intr, R, c)
    red = (img[..., 0] > 200) & (img[..., 1] < 60)
    ii, jj = np.nonzero(red)
    observed = np.array([jj.mean() + 0.5, ii.mean() + 0.5])  # pixel centres at +0.5
    x_cam = R @ (point - c)
    expected = (intr.K @ x_cam)[:2] / x_cam[2]
    assert observed == pytest.approx(expected, abs=0.5)


def test_depth_of_a_fronto_parallel_wall():
    r = Renderer(marker_scene([4.999, 4.0, 4.0]), noise_sigma=0)  # marker out of view
    intr = Intrinsics.from_hfov(64, 48, 60)
    depth = r.depth(intr, look_rotation(0.0), np.array([1.0, 0.0, 0.0]))
    assert np.allclose(depth, 4.0, atol=1e-3)


def test_photos_of_the_office_are_textured_and_fast_enough_to_render(tmp_path):
    from scenebot.scene.office import office

    scene = office(7)
    r = Renderer(scene)
    intr = Intrinsics.from_hfov(160, 120, 60)
    img = r.render(intr, look_rotation(0.3), np.array([scene.start.x, scene.start.y, 0.35]))
    assert img.shape == (120, 160, 3)
    assert img.std() > 20  # not a flat image
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 500


@pytest.mark.parametrize("scene_name", ["office", "flat"])
def test_the_shading_kernel_gives_the_numpy_references_colours(scene_name):
    """The taichi kernel against the float64 numpy shading it replaced, photo by photo (both
    built-in scenes: textures at every mip level, shiny whiteboards and metal, emissive
    lamps): within one grey level, and never a whole pixel apart."""
    from scenebot.config import WorldConfig
    from scenebot.scene.loader import load_world_scene

    scene = load_world_scene(WorldConfig(builtin=scene_name, seed=7))
    r = Renderer(scene, noise_sigma=0)
    intr = Intrinsics.from_hfov(160, 120, 60)
    rng = np.random.default_rng(3)
    lo, hi = scene.vertices.min(axis=0), scene.vertices.max(axis=0)
    hits = 0
    for k in range(6):
        c = np.array([*rng.uniform(lo[:2] + 0.5, hi[:2] - 0.5), scene.floor_z + 0.3 + 0.2 * k])
        R = look_rotation(float(rng.uniform(0, 2 * np.pi)), float(rng.uniform(-0.5, 0.7)))
        dirs = r._pixel_rays(intr, R)
        origins = np.broadcast_to(c, dirs.shape)
        hit = r.cast(origins, dirs)
        fast = r._shade(origins, dirs, hit, 1.0 / intr.fx)
        ref = r.shade_reference(origins, dirs, hit, 1.0 / intr.fx)
        hits += int((hit["prim"] >= 0).sum())
        assert fast.shape == ref.shape and fast.dtype == np.float32
        assert np.abs(fast - ref).max() <= 1.0, (scene_name, k)
    assert hits > 6 * 160 * 120 // 2  # the photos saw the scene


def test_jpeg_carries_the_focal_length_in_exif(tmp_path):
    img = np.random.default_rng(0).integers(0, 255, (48, 64, 3), dtype=np.uint8)
    p = write_jpeg(tmp_path / "a.jpg", img, focal_px=55.4256, sensor_width_mm=5.76)
    assert exif_focal_px(p) == pytest.approx(55.4256, rel=1e-4)
    with Image.open(p) as im:
        exif = im.getexif()
        assert im.format == "JPEG" and im.size == (64, 48)
        assert exif[0x010F] == "scenebot"
        f35 = exif.get_ifd(0x8769)[0xA405]
    assert f35 == round(55.4256 * math.hypot(36, 24) / math.hypot(64, 48))
    assert not (tmp_path / "a.jpg.part").exists()


def test_pycolmap_reads_the_focal_length_we_write(tmp_path):
    pycolmap = pytest.importorskip("pycolmap")
    img = np.random.default_rng(0).integers(0, 255, (480, 640, 3), dtype=np.uint8)
    f = 0.5 * 640 / math.tan(math.radians(30))
    write_jpeg(tmp_path / "a.jpg", img, focal_px=f, sensor_width_mm=5.76)
    cam = pycolmap.infer_camera_from_image(tmp_path / "a.jpg")
    assert cam.has_prior_focal_length
    assert cam.mean_focal_length() == pytest.approx(f, rel=0.01)
