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
