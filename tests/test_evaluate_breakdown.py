"""Where completeness is lost: photo view counts (visibility against the true scene), the
breakdown by view count and material, and the coverage curve by photo count (evaluation only)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from scenebot.evaluate.breakdown import (
    completeness_breakdown,
    count_views,
    coverage_by_photo_count,
    photo_view_counts,
    photo_visibility,
    texture_contrast,
)
from scenebot.evaluate.observable import sample_surface_weighted
from tests.fixtures.rooms import box_room

BOX = ((1.0, 1.0, 0.0), (1.6, 1.6, 0.5))
# a camera at (3.5, 1.3) at 0.35 m looking west (-x): OpenCV axes right = +y, down = -z
LOOK_WEST = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [-1.0, 0.0, 0.0]])
CENTRE = np.array([3.5, 1.3, 0.35])
# from the same centre looking east (+x): right = -y, down = -z
LOOK_EAST = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])


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


def test_coverage_by_photo_count_accumulates_the_photos_in_order():
    # 5 samples (areas 1, 2, 3, 4, 10), 5 photos; every 2 photos and the last
    w = np.array([1.0, 2.0, 3.0, 4.0, 10.0])
    vis = [np.array([0, 1]), np.array([1, 2]), np.array([], int), np.array([0, 3]), np.array([4])]
    cov = coverage_by_photo_count(iter(vis), w, step=2)  # read once: a generator will do
    assert cov["photos"] == [2, 4, 5]
    # after 2 photos: counts 1, 2, 1, 0, 0; after 4: 2, 2, 1, 1, 0; after 5: 2, 2, 1, 1, 1
    assert cov["seen_1"] == pytest.approx([6 / 20, 10 / 20, 1.0])
    assert cov["seen_2"] == pytest.approx([2 / 20, 3 / 20, 3 / 20])
    np.testing.assert_array_equal(count_views(vis, 5), [2, 2, 1, 1, 1])
    # unit weights: shares of the samples; a step dividing N ends on N once
    cov = coverage_by_photo_count(vis[:4], np.ones(5), step=1)
    assert cov["photos"] == [1, 2, 3, 4]
    assert cov["seen_1"] == pytest.approx([0.4, 0.6, 0.6, 0.8])
    assert cov["seen_2"] == pytest.approx([0.0, 0.2, 0.2, 0.4])
    assert coverage_by_photo_count([], w) == {"photos": [], "seen_1": [], "seen_2": []}
    with pytest.raises(ValueError, match="step"):
        coverage_by_photo_count(vis, w, step=0)


def test_coverage_curve_of_rendered_photos_ends_on_the_view_counts(samples):
    scene, pts, w, _ = samples
    # west twice (the second adds no new surface but sees it all twice), then east: disjoint
    poses = [(LOOK_WEST, CENTRE), (LOOK_WEST, CENTRE), (LOOK_EAST, CENTRE)]
    vis = list(photo_visibility(pts, poses, scene, hfov_deg=60.0))
    assert [v.dtype for v in vis] == [np.int32] * 3
    np.testing.assert_array_equal(vis[0], vis[1])
    assert len(vis[2]) > 50 and not np.intersect1d(vis[0], vis[2]).size
    assert np.all(pts[vis[2], 0] > 3.5)  # the east photo sees only what lies east of it
    views = photo_view_counts(pts, poses, scene, hfov_deg=60.0)
    np.testing.assert_array_equal(count_views(vis, len(pts)), views)
    cov = coverage_by_photo_count(vis, w, step=1)
    west, east = w[vis[0]].sum() / w.sum(), w[vis[2]].sum() / w.sum()
    assert cov["photos"] == [1, 2, 3]
    assert cov["seen_1"] == pytest.approx([west, west, west + east])
    assert cov["seen_2"] == pytest.approx([0.0, west, west])
    assert 0.05 < west < 0.5 and east > 0.002  # the east wall is 0.5 m away
    # the last point is the breakdown's photographed share over all photos
    b = completeness_breakdown(np.zeros(len(pts)), w, views, np.zeros(len(pts), int),
                               scene.materials)  # fmt: skip
    assert cov["seen_2"][-1] == b["photographed_share"]
    assert cov["seen_1"][-1] == pytest.approx(w[views >= 1].sum() / w.sum())
    # every 2 photos: n = 2 and N = 3
    assert coverage_by_photo_count(vis, w, step=2)["photos"] == [2, 3]
