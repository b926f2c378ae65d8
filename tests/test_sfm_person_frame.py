"""A person's frame (robot: photos) on synthetic camera sets with a known up (no images),
and the view graph that decides when global SfM maps a photo folder."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scenebot.sfm.mapping import connected_left_out
from scenebot.sfm.person_frame import (
    SCALE_UNKNOWN,
    TIE_BREAK,
    estimate_up,
    fit_person_frame,
    side_direction,
)

Z = np.array([0.0, 0.0, 1.0])


def _views(yaw: np.ndarray, elevation_deg: np.ndarray) -> np.ndarray:
    """(N, 3) optical axes with headings ``yaw`` (rad) and elevations (deg) in a z-up world."""
    e = np.radians(elevation_deg)
    return np.stack([np.cos(e) * np.cos(yaw), np.cos(e) * np.sin(yaw), np.sin(e)], 1)


def _image_ups(views: np.ndarray, roll_quarters: np.ndarray) -> np.ndarray:
    """(N, 3) image-up vectors of cameras looking along ``views``, each photo rolled by
    ``roll_quarters`` x 90 degrees (0: upright; 2: upside down)."""
    up0 = Z - (views @ Z)[:, None] * views
    up0 /= np.linalg.norm(up0, axis=1)[:, None]
    right = np.cross(views, up0)
    choices = np.stack([up0, right, -up0, -right])  # rolled 0, 90, 180, 270 degrees
    return choices[roll_quarters % 4, np.arange(len(views))]


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def _rotated_estimate(views, centers, ups, rng):
    """estimate_up on the set turned by a random rotation R; returns (up in the world frame,
    stats)."""
    R = _random_rotation(rng)
    up, stats = estimate_up(views @ R.T, centers @ R.T, ups @ R.T)
    return R.T @ up, stats


def _deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.acos(np.clip(float(a @ b), -1.0, 1.0)))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_ring_of_rolled_photos_looking_down(seed):
    """Like the temple: 16 photos on a ring looking 10 deg down at its centre, rolled 90 or
    270 degrees at random and three upside down (the mean image-up is meaningless): up
    within 1 deg, the sign from the cameras looking down, both axis cues agree."""
    rng = np.random.default_rng(seed)
    a = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    centers = np.stack([np.cos(a), np.sin(a), rng.normal(0, 0.01, 16)], 1)
    views = _views(a + np.pi, -10 + rng.normal(0, 1.0, 16))
    rolls = rng.choice([1, 3], 16)
    rolls[rng.choice(16, 3, replace=False)] = 2
    ups = _image_ups(views, rolls)
    up, stats = _rotated_estimate(views, centers, ups, rng)
    assert _deg(up, Z) < 1.0
    assert stats["sign_source"] == "cameras_look_down" and not stats["image_up_informative"]
    assert stats["sign_certain"]
    assert stats["optical_axes"]["model"] == "common_elevation"
    assert stats["cues_angle_deg"] < 2.0
    assert stats["mean_view_elevation_deg"] == pytest.approx(-10.0, abs=1.0)


def test_half_ring_looking_steeply_down_at_an_object():
    """A person walking half-way round a statue, looking 20 deg down: the optical axes share
    one elevation (a level-camera model would tilt the frame by ~20 deg)."""
    rng = np.random.default_rng(3)
    a = np.linspace(0, np.pi, 20)
    centers = np.stack([np.cos(a), np.sin(a), 0.4 + rng.normal(0, 0.03, 20)], 1)
    views = _views(a + np.pi + rng.normal(0, 0.05, 20), -20 + rng.normal(0, 2.0, 20))
    ups = _image_ups(views, np.zeros(20, int))
    up, stats = _rotated_estimate(views, centers, ups, rng)
    assert _deg(up, Z) < 4.0
    assert stats["sign_source"] == "image_up" and stats["sign_cues_agree"]


def test_facade_strip_of_upright_photos():
    """Camera centres on a line, every photo facing the facade: neither cue determines up on
    its own, together they do; upright photos give the sign."""
    rng = np.random.default_rng(4)
    n = 20
    centers = np.stack([np.linspace(0, 10, n), rng.normal(0, 0.2, n), rng.normal(0, 0.05, n)], 1)
    views = _views(np.pi / 2 + rng.normal(0, 0.05, n), rng.normal(0, 2.0, n))
    ups = _image_ups(views, np.zeros(n, int))
    up, stats = _rotated_estimate(views, centers, ups, rng)
    assert _deg(up, Z) < 3.0
    assert not stats["camera_centres"]["determines_axis"]
    assert stats["sign_source"] == "image_up" and stats["image_up_mean"] > 0.9


def test_climbing_stairs_while_looking_around_does_not_tilt_up():
    """Centres rising 30 deg along a line (stairs) do not tilt up when the optical axes,
    level all around, determine it: the centres only break ties."""
    rng = np.random.default_rng(5)
    n = 24
    t = np.linspace(0, 5, n)
    centers = np.stack([t, rng.normal(0, 0.1, n), t * math.tan(math.radians(30))], 1)
    views = _views(rng.uniform(0, 2 * np.pi, n), rng.normal(0, 3.0, n))
    ups = _image_ups(views, np.zeros(n, int))
    up, stats = _rotated_estimate(views, centers, ups, rng)
    assert _deg(up, Z) < 4.0
    assert stats["camera_centres_weight"] == TIE_BREAK


def test_an_uncertain_sign_is_warned():
    """Rolled photos of a facade taken level: nothing says which way is up; the frame says
    so in its warnings."""
    rng = np.random.default_rng(6)
    n = 20
    centers = np.stack([np.linspace(0, 10, n), rng.normal(0, 0.2, n), rng.normal(0, 0.05, n)], 1)
    views = _views(np.pi / 2 + rng.normal(0, 0.05, n), rng.normal(0, 2.0, n))
    ups = _image_ups(views, np.tile([1, 3], n // 2))
    names = [f"p{k:02d}.jpg" for k in range(n)]
    fit = fit_person_frame(names, centers, ups, views, known_distance=None, up_photo=None)
    assert not fit.stats["up"]["sign_certain"]
    assert any("uncertain" in w for w in fit.stats["warnings"])
    assert SCALE_UNKNOWN in fit.stats["warnings"]


def test_mostly_upside_down_photos_decide_the_sign_with_a_warning():
    """Image-up vectors that agree (most photos upside down) decide the sign even against
    the cameras' look-down; the disagreement is a warning (EXIF-rotated phone photos)."""
    rng = np.random.default_rng(8)
    a = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    centers = np.stack([np.cos(a), np.sin(a), rng.normal(0, 0.01, 16)], 1)
    views = _views(a + np.pi, -10 + rng.normal(0, 1.0, 16))
    ups = _image_ups(views, np.full(16, 2))
    names = [f"p{k:02d}.jpg" for k in range(16)]
    fit = fit_person_frame(names, centers, ups, views, known_distance=None, up_photo=None)
    up = fit.stats["up"]
    assert up["sign_source"] == "image_up" and up["sign_cues_agree"] is False
    assert _deg(fit.R.T @ Z, -Z) < 1.0
    assert any("image-up vectors say up" in w for w in fit.stats["warnings"])


def test_person_frame_conventions_scale_and_override():
    """z up with z = 0 at the median camera height, origin below the centroid, x along the
    first photo's view; metres from a known distance; sfm.up_photo overrides up."""
    rng = np.random.default_rng(7)
    n = 12
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    world_c = np.stack([3 * np.cos(a), 3 * np.sin(a), 1.5 + rng.normal(0, 0.02, n)], 1)
    views = _views(a + np.pi, np.full(n, -5.0))
    ups = _image_ups(views, rng.integers(0, 4, n))
    R, s = _random_rotation(rng), 0.37  # the model's frame: turned and scaled
    C, U, V = s * world_c @ R.T + [5.0, -2.0, 1.0], ups @ R.T, views @ R.T
    names = [f"p{k:02d}.jpg" for k in range(n)]
    dist = float(np.linalg.norm(world_c[0] - world_c[6]))
    fit = fit_person_frame(names, C, U, V, known_distance=(names[0], names[6], dist), up_photo=None)
    X = fit.scale * C @ fit.R.T + fit.t
    assert fit.scale_source == "known_distance" and fit.scale == pytest.approx(1 / s, rel=1e-6)
    assert np.median(X[:, 2]) == pytest.approx(0.0, abs=1e-9)
    assert np.allclose(X[:, :2].mean(0), 0.0, atol=1e-9)
    d = np.linalg.norm(X[:, None] - X[None], axis=2)
    assert np.allclose(d, np.linalg.norm(world_c[:, None] - world_c[None], axis=2), atol=1e-6)
    v0 = fit.R @ V[0]
    assert math.degrees(math.atan2(v0[1], v0[0])) == pytest.approx(0.0, abs=1e-6)
    assert v0[2] < 0  # looking down: z is up
    assert SCALE_UNKNOWN not in fit.stats["warnings"]
    # override: photo 3 was rolled; its side that points up is the one the user names
    k = 3
    side = next(
        sd for sd in ("top", "bottom", "left", "right")
        if side_direction(ups[k], views[k], sd) @ Z > 0.9
    )  # fmt: skip
    over = fit_person_frame(names, C, U, V, known_distance=None, up_photo=(names[k], side))
    assert _deg(over.R.T @ Z, R @ side_direction(ups[k], views[k], side)) < 1e-4
    assert over.stats["up"]["source"] == f"sfm.up_photo ({side} of {names[k]})"
    with pytest.raises(ValueError, match=r"sfm\.up_photo names 'nope\.jpg'"):
        fit_person_frame(names, C, U, V, known_distance=None, up_photo=("nope.jpg", "top"))
    with pytest.raises(ValueError, match=r"sfm\.known_distance"):
        fit_person_frame(names, C, U, V, known_distance=("x.jpg", names[1], 1.0), up_photo=None)


def test_photos_the_view_graph_connects_to_the_model():
    """Global SfM runs only for photos outside the model that verified pairs connect to it
    (a chain counts; an island does not, nor photos outside the set)."""
    graph = {
        "a": {"b"}, "b": {"a", "c"}, "c": {"b", "d"}, "d": {"c"},
        "x": {"y"}, "y": {"x"}, "e": {"a"},
    }  # fmt: skip
    names = ["a", "b", "c", "d", "x", "y"]  # "e" is not in this set
    assert connected_left_out(graph, names, {"a", "b"}) == ["c", "d"]
    assert connected_left_out(graph, names, {"a", "b", "c", "d"}) == []


def test_a_global_model_that_disagrees_with_the_incremental_one_is_measured(tmp_path):
    """sfm.global_max_disagreement: the same cameras in another frame (a similarity) agree
    (0); a model with its cameras scattered does not (about 1: residuals of the map's size)."""
    import pycolmap

    from scenebot.geometry import look_rotation
    from scenebot.sfm.mapping import _disagreement
    from scenebot.testing.score import default_intrinsics, write_colmap_model

    rng = np.random.default_rng(0)
    n = 8
    C = np.c_[rng.uniform(0, 4, n), rng.uniform(0, 3, n), np.full(n, 0.3)]
    R = np.array([look_rotation(h) for h in rng.uniform(0, 2 * np.pi, n)])
    pts = rng.uniform([0, 0, 0], [4, 3, 2], (60, 3))

    def model(name, centres):
        t = -np.einsum("kij,kj->ki", R, centres)
        write_colmap_model(tmp_path / name, default_intrinsics(), R, t, pts, np.ones((n, 60), bool))
        return pycolmap.Reconstruction(str(tmp_path / name))

    inc = model("inc", C)
    same = model("same", C)  # pycolmap keeps the frame: a similarity is fitted anyway
    scattered = model("scattered", C + rng.normal(0, 2.0, C.shape))
    assert _disagreement(inc, same) < 1e-6
    assert _disagreement(inc, scattered) > 0.3
    assert _disagreement(inc, None) is None
