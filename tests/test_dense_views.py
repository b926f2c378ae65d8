"""Source-view selection and depth ranges from a sparse model."""

import numpy as np
import pytest

from scenebot.dense.views import select_views
from scenebot.testing.dense import box_room_scene, make_dataset


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    sc = box_room_scene()
    # 5 cameras looking at +x, one looking backwards (-x): no shared points with the others
    centers = np.array([[0, y, 0] for y in np.linspace(-0.4, 0.4, 5)] + [[0.0, 0.0, 0.0]])
    headings = np.array([0.0] * 5 + [np.pi])
    out = tmp_path_factory.mktemp("views")
    return make_dataset(out, sc, centers, headings, 160, 120, num_points=3000)


def test_sources_and_ranges(rig):
    rec, views = rig
    plans, isolated = select_views(rec, num_sources=3, min_shared_points=10, min_angle_deg=1.0)
    assert isolated == ["view_005.jpg"]
    assert len(plans) == 5
    for p in plans:
        assert p.image_id not in p.sources
        assert 1 <= len(p.sources) <= 3
        assert 5 + 1 not in p.sources  # never the backwards camera
        assert all(n >= 10 for n in p.shared_points)
        assert all(a >= 1.0 for a in p.median_angle_deg)
        true = views[p.image_id - 1].depth
        lo, hi = np.percentile(true[true > 0], [5, 95])
        assert p.depth_range[0] < lo and p.depth_range[1] > hi
    # a large minimum angle leaves only wide baselines
    plans, _ = select_views(rec, num_sources=4, min_angle_deg=6.0)
    assert all(min(p.median_angle_deg) >= 6.0 for p in plans)


def test_too_few_registered(rig):
    rec, _ = rig
    import pycolmap

    one = pycolmap.Reconstruction(rec)
    for i in list(one.reg_image_ids())[1:]:
        one.deregister_frame(one.image(i).frame_id)
    with pytest.raises(ValueError, match="1 registered image"):
        select_views(one)


def test_a_wide_baseline_outranks_a_close_neighbour_with_more_points():
    """Turn-in-place neighbours share many points at 2 degrees; a view from the next circle
    shares fewer at 12. The squared angle weight puts the wide one first."""
    from scenebot.dense.views import _angle_weight

    close, wide = 240 * _angle_weight(2.0, 1.0, 10.0), 90 * _angle_weight(12.0, 1.0, 10.0)
    assert wide > close
    assert _angle_weight(0.5, 1.0, 10.0) == 0.0  # below the minimum angle: never
    assert _angle_weight(60.0, 1.0, 10.0) < _angle_weight(30.0, 1.0, 10.0) == 1.0
