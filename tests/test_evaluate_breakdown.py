"""Where completeness is lost: photo view counts (visibility against the true scene) and the
breakdown by view count and material (evaluation only)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from conftest import box_room

from scenebot.evaluate.breakdown import (
    completeness_breakdown,
    photo_view_counts,
    texture_contrast,
)
from scenebot.evaluate.observable import sample_surface_weighted

BOX = ((1.0, 1.0, 0.0), (1.6, 1.6, 0.5))
# a camera at (3.5, 1.3) at 0.35 m looking west (-x): OpenCV axes right = +y, down = -z
LOOK_WEST = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [-1.0, 0.0, 0.0]])
CENTRE = np.array([3.5, 1.3, 0.35])


@pytest.fixture(scope="module")
def samples():
    scene = box_room(obstacles=[BOX])
    pts, w, tid = sample_surface_weighted(scene.vertices, scene.triangles, 0.05, seed=2)
    return scene, pts, w, tid


def test_view_counts_follow_the_frustum_and_occlusion(samples):
    scene, pts, _, _ = samples
    views = photo_view_counts(pts, [(LOOK_WEST, CENTRE)] * 2, scene, hfov_deg=60.0)
    x, y, z = pts.T
    behind = x > 3.99  # the east wall, behind the camera
    box_face = (np.abs(x - 1.6) < 1e-6) & (y > 1.05) & (y < 1.55) & (z > 0.05) & (z < 0.45)
    shadow = (x < 1e-6) & (np.abs(y - 1.3) < 0.15) & (np.abs(z - 0.35) < 0.08)
    west_open = (x < 1e-6) & (y > 0.2) & (y < 0.6) & (z > 0.9) & (z < 1.3)
    assert behind.sum() > 50 and box_face.sum() > 50 and shadow.sum() > 5
    assert west_open.sum() > 20
    assert np.all(views[behind] == 0)
    assert np.all(views[box_face] == 2)  # two photos from the same pose
    assert np.all(views[shadow] == 0)  # the west wall behind the box: occluded
    assert np.all(views[west_open] == 2)


def test_breakdown_splits_the_area_by_views_and_material():
    flat = SimpleNamespace(name="paint", texture=np.full((4, 4, 3), 200, np.uint8))
    rng = np.random.default_rng(0)
    busy = SimpleNamespace(name="poster", texture=rng.integers(0, 256, (16, 16, 3), np.uint8))
    # 6 samples: paint (area 3: 1+1+1), poster (area 1.5: 0.5 x 3)
    d = np.array([0.005, 0.5, 0.5, 0.005, 0.015, 0.5])
    w = np.array([1.0, 1.0, 1.0, 0.5, 0.5, 0.5])
    views = np.array([3, 0, 1, 2, 5, 2])
    mat = np.array([0, 0, 0, 1, 1, 1])
    b = completeness_breakdown(d, w, views, mat, [flat, busy], (0.01, 0.02))
    total = w.sum()
    assert sum(c["area_share"] for c in b["by_views"]) == pytest.approx(1.0)
    by_views = {c["views"]: c for c in b["by_views"]}
    assert by_views["0"]["area_share"] == pytest.approx(1.0 / total)
    assert by_views["0"]["completeness"]["2cm"] == 0.0
    assert by_views[">=2"]["area_share"] == pytest.approx(2.5 / total)
    assert by_views[">=2"]["completeness"]["1cm"] == pytest.approx(1.5 / 2.5)
    assert by_views[">=2"]["completeness"]["2cm"] == pytest.approx(2.0 / 2.5)
    assert b["photographed_share"] == pytest.approx(2.5 / total)
    assert b["completeness_where_photographed"] == by_views[">=2"]["completeness"]
    paint, poster = b["by_material"]  # largest area first
    assert paint["material"] == "paint" and paint["area_share"] == pytest.approx(3 / total)
    assert paint["photographed_share"] == pytest.approx(1 / 3)
    assert paint["completeness"]["2cm"] == pytest.approx(1 / 3)
    assert poster["completeness"]["2cm"] == pytest.approx(2 / 3)
    assert paint["texture_contrast"] == 0.0 < 50 < poster["texture_contrast"]
    assert texture_contrast(np.zeros((2, 2))) == 0.0
