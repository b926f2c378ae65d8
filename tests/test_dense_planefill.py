"""Plane completion of depth maps: plane detection, hole filling bounded by the plane's own
measured neighbours, nothing filled across a nearer object, depth behind a plane culled."""

from __future__ import annotations

import numpy as np
import pytest

from scenebot.dense.config import PlaneFillConfig
from scenebot.dense.planes.detect import detect_planes, detect_settings
from scenebot.dense.planes.fill import fill_view, fill_view_settings
from scenebot.dense.planes.geometry import backproject
from scenebot.dense.planes.phantoms import plane_evidence, validate_planes

W, H, F = 160, 120, 100.0
K = np.array([[F, 0, W / 2], [0, F, H / 2], [0, 0, 1.0]])
R, T = np.eye(3), np.zeros(3)  # camera at the origin looking along +z
NORMAL = np.zeros((H, W, 3), np.float32)

CFG = PlaneFillConfig()
#: the settings of these tests unless they say otherwise: the config's, but for extents
#: closed over 2 cells, planes kept as fitted (snap_deg 0) and the same_plane fill rule with
#: the neighbours' planes
TEST_CFG = PlaneFillConfig(
    extent_close_cells=2, snap_deg=0.0, fill_rule="same_plane", fill_planes="neighbours"
)
#: the settings of carved_hulls and occluded_fill (the config's)
HULLS = dict(
    distance_m=CFG.label_distance_m,
    rel_distance=CFG.label_rel_distance,
    min_rays=CFG.carve_min_rays,
)
OCCLUSION = dict(cell_px=CFG.cell_px, min_points=CFG.occlusion_min_points)
EDGE = CFG.sparse_veto_max_edge_px  # sparse_contradicted_fill's longest triangle edge


def detect_kw(**kw) -> dict:
    """detect_planes' settings as the stage derives them from TEST_CFG, with the test's own."""
    return {**detect_settings(TEST_CFG), **kw}


def fill_kw(**kw) -> dict:
    """fill_view's settings as the stage derives them from TEST_CFG, with the test's own."""
    return {**fill_view_settings(TEST_CFG), **kw}


def wall(depth=3.0) -> np.ndarray:
    return np.full((H, W), depth, np.float32)


def planes_of(*maps):
    pts = np.concatenate([backproject(d, K, R, T)[d > 0] for d in maps])
    return detect_planes(pts, **detect_kw(distance_m=0.01, min_share=0.05, cell_m=0.1))


def test_two_noisy_planes_are_found_once_each():
    rng = np.random.default_rng(0)
    floor = np.c_[rng.uniform(-2, 2, (4000, 2)), rng.normal(-0.35, 0.006, 4000)]
    wallp = np.c_[np.full(3000, 3.0) + rng.normal(0, 0.006, 3000), rng.uniform(-2, 2, (3000, 2))]
    planes = detect_planes(np.r_[floor, wallp], **detect_kw(distance_m=0.01, min_share=0.05))
    assert len(planes) == 2  # the noisy floor is not peeled into slices
    fl, wl = planes
    assert abs(fl.normal[2]) > np.cos(np.radians(1)) and abs(wl.normal[0]) > np.cos(np.radians(1))
    assert abs(abs(fl.offset) - 0.35) < 0.005 and abs(abs(wl.offset) - 3.0) < 0.005
    assert fl.area_m2 == pytest.approx(16.0, rel=0.15)
    assert (
        fl.inside(np.array([[0.0, 0.0, -0.35]]))[0] and not fl.inside(np.array([[5, 5, -0.35]]))[0]
    )


def test_a_plain_patch_of_a_wall_is_filled_with_the_wall():
    d = wall()
    d[50:60, 70:80] = 0  # plain paint: no depth over 30 x 30 cm
    planes = planes_of(d)
    fd, fn, filled, culled = fill_view(d, NORMAL, K, R, T, planes, (0.5, 10.0), **fill_kw())
    assert filled == 100 and culled == 0
    assert np.allclose(fd[50:60, 70:80], 3.0, atol=1e-3)
    # normals face the camera (negative z in the camera frame)
    assert np.allclose(fn[55, 75], (0, 0, -1), atol=1e-3)


def test_fill_stays_within_the_planes_extent():
    """A 1.8 x 1.2 m plain region is beyond the extent's closing: only its rim (the
    extent's margin and closing) is filled, the middle stays empty."""
    d = wall()
    d[40:80, 50:110] = 0
    planes = planes_of(d)
    fd, _, filled, _ = fill_view(d, NORMAL, K, R, T, planes, (0.5, 10.0), **fill_kw())
    assert 0 < filled < 40 * 60
    assert np.all(fd[55:65, 70:90] == 0)
    assert np.allclose(fd[fd > 0], 3.0, atol=1e-3)


def test_a_plain_face_before_the_wall_is_not_filled_with_the_wall():
    rng = np.random.default_rng(1)
    d = wall()
    d[30:90, 40:120] = rng.uniform(1.8, 2.2, (60, 80))  # a box's edges, off every plane
    d[34:86, 44:116] = 0  # its plain face
    planes = planes_of(d)
    fd, _, _, _ = fill_view(d, NORMAL, K, R, T, planes, (0.5, 10.0), **fill_kw())
    assert np.all(fd[40:80, 50:110] == 0)  # its middle stays empty


def test_depth_behind_a_plane_is_culled_and_replaced():
    d = wall()
    d[60:63, 80:83] = 5.0  # a match through the wall
    planes = planes_of(d)
    fd, _, filled, culled = fill_view(d, NORMAL, K, R, T, planes, (0.5, 10.0), **fill_kw())
    assert culled == 9 and filled == 9
    assert np.allclose(fd[60:63, 80:83], 3.0, atol=1e-3)
    keep, _, _, culled = fill_view(
        d, NORMAL, K, R, T, planes, (0.5, 10.0), **fill_kw(cull_behind=False)
    )
    assert culled == 0 and np.all(keep[60:63, 80:83] == 5.0)


def test_phantom_planes_are_dropped_and_the_real_wall_kept():
    """A wall at 3 m seen in three maps; in one of them a transient mismatch at 2 m (a plane
    floating in the room, seen through in the other maps); in all of them an aliased patch at
    4 m interleaved with the wall (a phantom behind the wall, as a repeating carpet makes one
    beneath the floor)."""
    transient, steady = wall(), wall()
    transient[20:50, 20:50] = 2.0
    for d in (transient, steady):
        d[70:100, 100:130][::2, ::2] = 4.0
        d[70:100, 100:130][1::2, 1::2] = 4.0
    maps = (transient, steady, steady.copy())
    pts = np.concatenate([backproject(d, K, R, T)[d > 0] for d in maps])
    planes = detect_planes(pts, **detect_kw(distance_m=0.01, min_share=0.005, cell_m=0.1))
    depths = sorted(round(-p.offset / p.normal[2], 2) for p in planes)
    assert depths == [2.0, 3.0, 4.0]
    on = np.zeros(3, np.int64)
    behind = np.zeros(3, np.int64)
    hidden = np.zeros((3, 3), np.int64)
    for d in maps:
        a, b, c = plane_evidence(
            d, K, R, T, planes, distance_m=CFG.label_distance_m,
            rel_distance=CFG.label_rel_distance, stride=2,
        )  # fmt: skip
        on, behind, hidden = on + a, behind + b, hidden + c
    keep, why = validate_planes(planes, on, behind, hidden, max_seen_through=1.0, max_hidden=0.5)
    depth_of = {j: round(-p.offset / p.normal[2], 2) for j, p in enumerate(planes)}
    assert [depth_of[j] for j in keep] == [3.0]
    assert {depth_of[j]: w.split(":")[0] for j, w in why.items()} == {
        2.0: "seen through",
        4.0: "hidden",
    }
    # the evidence itself: all that lies behind the wall is the phantom at 4 m
    wall_j = keep[0]
    far = next(j for j in depth_of if depth_of[j] == 4.0)
    assert hidden[far, wall_j] > 0.9 * on[far]
    assert behind[wall_j] == hidden[far, wall_j] < 0.1 * on[wall_j]


def test_oriented_ransac_finds_the_steps_not_the_slope_across_them():
    """Six 10 cm steps: by position alone the slope through their edges holds more points
    than any one tread; with the stereo normals only treads and risers are planes."""
    rng = np.random.default_rng(2)
    pts, nrm = [], []
    for i in range(6):
        tread = np.c_[rng.uniform(i * 0.1, (i + 1) * 0.1, 800), rng.uniform(0, 1, 800)]
        pts.append(np.c_[tread[:, 0], tread[:, 1], np.full(800, (i + 1) * 0.1)])
        nrm.append(np.tile([0.0, 0.0, 1.0], (800, 1)))
        riser = np.c_[rng.uniform(0, 1, 800), rng.uniform(i * 0.1, (i + 1) * 0.1, 800)]
        pts.append(np.c_[np.full(800, i * 0.1), riser[:, 0], riser[:, 1]])
        nrm.append(np.tile([-1.0, 0.0, 0.0], (800, 1)))
    pts = np.concatenate(pts) + rng.normal(0, 0.002, (9600, 3))
    nrm = np.concatenate(nrm) + rng.normal(0, 0.1, (9600, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    kw = dict(distance_m=0.015, min_share=0.05, cell_m=0.05)
    slope = 0.0
    for p in detect_planes(pts, **detect_kw(**kw)):
        slope = max(slope, min(abs(p.normal[0]), abs(p.normal[2])))
    assert slope > 0.5  # by position alone, a plane at about 45 degrees
    planes = detect_planes(pts, normals=nrm, **detect_kw(normal_deg=30, **kw))
    assert len(planes) == 12
    for p in planes:  # every one a tread or a riser
        assert max(abs(p.normal[0]), abs(p.normal[2])) > np.cos(np.radians(2))


def _room_view():
    """A camera at the origin looking along +z into a corner region: the wall z = 3 m and
    the floor y = 0.5 m (camera y points down), both plain except for a textured rim."""
    v = np.mgrid[0:H, 0:W][0] + 0.5
    ray_y = (v - K[1, 2]) / K[1, 1]
    with np.errstate(divide="ignore"):
        floor_z = np.where(ray_y > 0, 0.5 / ray_y, np.inf)
    truth = np.minimum(floor_z, 3.0).astype(np.float32)
    return truth


def test_a_plain_corner_is_filled_with_the_planes_that_bound_it():
    """Wall and floor meet; both are measured only along the image border. With the
    bounding-planes rule (and the boundary planes' hulls as extents) each hole pixel lands
    on the plane its ray meets first: wall pixels on the wall, floor pixels on the floor."""
    from scenebot.dense.planes.extents import carved_hulls

    truth = _room_view()
    d = np.zeros_like(truth)
    d[:8], d[-8:], d[:, :8], d[:, -8:] = truth[:8], truth[-8:], truth[:, :8], truth[:, -8:]
    planes = planes_of(d)
    assert len(planes) == 2
    for pl, ext in zip(planes, carved_hulls(planes, [(d, K, R, T)], **HULLS), strict=True):
        pl.occupied = ext
    _, _, filled_same, _ = fill_view(d, NORMAL, K, R, T, planes, (0.2, 10.0), **fill_kw())
    front, _, filled_front, _ = fill_view(
        d, NORMAL, K, R, T, planes, (0.2, 10.0), **fill_kw(bounding_planes=True)
    )
    hole = d == 0
    assert filled_front > filled_same  # holes bounded by two planes are filled too
    got = front[hole] > 0
    assert got.mean() > 0.7
    assert np.allclose(front[hole][got], truth[hole][got], rtol=1e-3)


def test_a_boundary_wall_spans_the_plain_paint_between_its_posters():
    """Posters near the corners of a plain wall: its cells hold only them, the carved hull
    spans the wall between them, and a doorway seen through is carved out."""
    from scenebot.dense.planes.extents import carved_hulls

    d = wall()
    keep = np.zeros_like(d, bool)
    for r0, c0 in ((5, 5), (5, 130), (90, 5), (90, 130)):
        keep[r0 : r0 + 25, c0 : c0 + 25] = True
    d[~keep] = 0
    door = wall()
    door[:, :] = 0
    door[40:80, 70:90] = 6.0  # the room beyond a doorway in the wall, seen through it
    planes = planes_of(d)
    (ext,) = carved_hulls(planes, [(d, K, R, T), (door, K, R, T)], stride=1, **HULLS)
    pl = planes[0]
    middle = backproject(wall(), K, R, T)[50:70, 40:60].reshape(-1, 3)
    assert not pl.inside(middle).any()  # its cells: the posters only
    pl.occupied = ext
    assert pl.inside(middle).all()  # the hull spans the plain paint
    doorway = backproject(wall(), K, R, T)[50:70, 76:84].reshape(-1, 3)
    assert not pl.inside(doorway).any()  # seen through: carved


def test_a_box_face_is_not_widened_past_its_cells():
    """A plane with the room measured behind it (a box face 2 m away before the 3 m wall)
    is no boundary: it keeps its own cells."""
    from scenebot.dense.planes.extents import carved_hulls

    d = wall()
    d[20:45, 20:45] = 2.0
    d[75:100, 115:140] = 2.0  # two textured corners of a plain box face at 2 m
    planes = planes_of(d)
    face = next(j for j, p in enumerate(planes) if abs(abs(p.offset) - 2.0) < 0.01)
    exts = carved_hulls(planes, [(d, K, R, T)], **HULLS)
    assert np.array_equal(exts[face], planes[face].occupied)
    wallj = 1 - face
    assert exts[wallj].sum() >= planes[wallj].occupied.sum()


def test_a_plane_known_to_bound_the_room_is_widened_whatever_is_measured_past_it():
    """The ceiling comes from find_ceiling's own test (the room's top: nothing measured above
    it, allowing for grazing rays a few cm off), and its few hundred points cannot also pass
    carved_hulls' count of points beyond against those on it: a plane passed as known is a
    boundary and spans its hull, as the box face above does here."""
    from scenebot.dense.planes.extents import carved_hulls

    d = wall()
    d[20:45, 20:45] = 2.0
    d[75:100, 115:140] = 2.0
    planes = planes_of(d)
    face = next(j for j, p in enumerate(planes) if abs(abs(p.offset) - 2.0) < 0.01)
    exts = carved_hulls(planes, [(d, K, R, T)], known=[face], **HULLS)
    assert planes[face].boundary
    # widened to its hull (less the cells the wall behind is measured through)
    assert exts[face].sum() > planes[face].occupied.sum()
    assert np.array_equal(exts[face] & planes[face].occupied, planes[face].occupied)


def test_a_shadow_plane_a_few_centimetres_off_is_dropped():
    """Three views put the wall at 3.00 m, one (a slightly wrong pose) at 2.94 m: the shadow
    is as large in points as the wall but fewer views support it."""
    from scenebot.dense.planes.phantoms import shadow_planes

    wall_pts = backproject(wall(3.0), K, R, T).reshape(-1, 3)
    shadow_pts = backproject(wall(2.94), K, R, T).reshape(-1, 3)
    planes = detect_planes(
        np.r_[wall_pts, shadow_pts], **detect_kw(distance_m=0.01, min_share=0.05)
    )
    assert len(planes) == 2
    depth = [round(-p.offset / p.normal[2], 2) for p in planes]
    support = np.array([3 if abs(z - 3.0) < 0.01 else 1 for z in depth])
    why = shadow_planes(planes, support, max_gap_m=0.1, max_angle_deg=CFG.merge_angle_deg)
    assert [depth[j] for j in why] == [2.94]
    close = shadow_planes(planes, support, max_gap_m=0.03, max_angle_deg=CFG.merge_angle_deg)
    assert close == {}  # 6 cm apart: both kept


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_wall_whose_depth_spreads_over_several_slabs_is_one_plane_at_its_middle(seed):
    """A plain wall's measured points spread 2.5 cm either way around 3.03 m (stereo noise
    at that distance), with the floor: RANSAC's 1.5 cm slab may sit anywhere in the spread
    and leave the rest as a second plane 3-4 cm away; the wall comes out as one plane
    within 5 mm of its middle (an office wall was found 2 cm off, its other half 4 cm
    away)."""
    rng = np.random.default_rng(seed)
    n = 20000
    wallp = np.c_[rng.uniform(-2, 2, n), rng.uniform(-0.35, 2.2, n), rng.normal(3.03, 0.025, n)]
    floor = np.c_[rng.uniform(-2, 2, n), np.full(n, -0.35), rng.uniform(0.5, 3.0, n)]
    nrm = np.r_[np.tile([0.0, 0.0, -1.0], (n, 1)), np.tile([0.0, 1.0, 0.0], (n, 1))]
    kw = detect_kw(normal_deg=30, min_share=0.02, cell_m=0.1, snap_deg=CFG.snap_deg)
    planes = detect_planes(np.r_[wallp, floor], normals=nrm, **kw)
    walls = [p for p in planes if abs(p.normal[2]) > 0.99]
    assert len(walls) == 1
    assert abs(-walls[0].offset / walls[0].normal[2] - 3.03) < 0.005
    assert walls[0].inliers > 0.7 * n  # both halves' points hold its extent


def test_two_surfaces_farther_apart_than_two_ransac_distances_stay_two_planes():
    """A wall at 3.00 m and a panel 4 cm before it (sharp, 1 cm RANSAC distance): each
    keeps its own plane and offset."""
    pts = np.r_[backproject(wall(3.0), K, R, T).reshape(-1, 3),
                backproject(wall(2.96), K, R, T).reshape(-1, 3)[::2]]  # fmt: skip
    planes = detect_planes(pts, **detect_kw(distance_m=0.01, min_share=0.05))
    assert sorted(round(-p.offset / p.normal[2], 3) for p in planes) == [2.96, 3.0]


def test_a_hole_beside_an_objects_edge_is_left_empty_there():
    """A plain strip of wall next to an object (measured, off every plane): the strip is
    filled with the wall, but not within edge_px of the object, where the hole could as well
    be the object's side."""
    from scenebot.dense.planes.extents import carved_hulls

    rng = np.random.default_rng(3)
    d = wall()
    d[:, 80:120] = rng.uniform(1.8, 2.2, (H, 40))  # an object before the wall
    d[30:90, 68:80] = 0  # plain wall between them
    planes = planes_of(d)
    for pl, ext in zip(planes, carved_hulls(planes, [(d, K, R, T)], **HULLS), strict=True):
        pl.occupied = ext
    fd, _, filled, _ = fill_view(
        d, NORMAL, K, R, T, planes, (0.5, 10.0), **fill_kw(bounding_planes=True)
    )
    assert filled > 0
    assert np.allclose(fd[40:80, 68:74], 3.0, atol=1e-3)  # the strip, away from the edge
    assert np.all(fd[40:80, 77:80] == 0)  # within 3 px of the object: empty


def test_a_rug_within_the_ransac_band_does_not_tilt_the_floor():
    """A rug 1.2 cm thick along one side lies within RANSAC's band of the floor: a plain
    least-squares refit tilts the floor towards it (0.04 deg here; the office's floor came
    out 0.2 deg off, its ceiling then 1-3 cm off across the room), the robust refit does not;
    the floor's offset is the floor's, not a compromise with the rug."""
    rng = np.random.default_rng(6)
    floor = np.c_[rng.uniform(-3, 3, (20000, 2)), rng.normal(-0.35, 0.002, 20000)]
    rug = np.c_[rng.uniform(2, 3, 2000), rng.uniform(-3, 3, 2000), rng.normal(-0.338, 0.002, 2000)]
    pts = np.r_[floor, rug]
    centred = pts - pts.mean(0)
    plain = np.linalg.svd(centred, full_matrices=False)[2][-1]
    assert np.degrees(np.arccos(abs(plain[2]))) > 0.03  # what a least-squares refit does
    (fl,) = detect_planes(pts, **detect_kw(distance_m=0.015, min_share=0.05, cell_m=0.1))
    assert np.degrees(np.arccos(abs(fl.normal[2]))) < 0.01
    assert abs(fl.offset / fl.normal[2]) == pytest.approx(0.35, abs=0.001)


def test_walls_are_snapped_upright_and_floors_flat():
    """A wall measured 1.5 degrees off vertical (a few biased patches) stands upright after
    snapping to the floor's normal, at its inliers' median offset; snap_deg 0 keeps it."""
    rng = np.random.default_rng(4)
    floor = np.c_[rng.uniform(0, 4, (3000, 2)), rng.normal(-0.35, 0.003, 3000)]
    yz = np.c_[rng.uniform(0, 4, 3000), rng.uniform(-0.35, 2.2, 3000)]
    tilt = np.tan(np.radians(1.5))
    wallp = np.c_[3.0 + tilt * yz[:, 1] + rng.normal(0, 0.003, 3000), yz]
    kw = dict(distance_m=0.02, min_share=0.05, cell_m=0.1)
    raw = detect_planes(np.r_[floor, wallp], **detect_kw(**kw))
    snapped = detect_planes(np.r_[floor, wallp], **detect_kw(snap_deg=3.0, **kw))
    wall_raw = next(p for p in raw if abs(p.normal[0]) > 0.9)
    wall_s = next(p for p in snapped if abs(p.normal[0]) > 0.9)
    floor_s = next(p for p in snapped if abs(p.normal[2]) > 0.9)
    assert abs(wall_raw.normal[2]) > np.sin(np.radians(1.0))  # fitted: tilted
    assert wall_s.normal @ floor_s.normal == pytest.approx(0.0, abs=1e-9)  # snapped: upright
    assert abs(floor_s.normal[2]) > np.cos(np.radians(0.2))
    x_mid = 3.0 + tilt * np.median(yz[:, 1])
    assert abs(-wall_s.offset / wall_s.normal[0]) == pytest.approx(x_mid, abs=0.01)


def test_a_wall_fitted_5_degrees_off_stands_upright_with_the_default_snap():
    """RANSAC over a wall and its copy a few cm in front (a slightly misregistered circle)
    fits a plane tilted by degrees; the default snap_deg makes it a wall again, which the
    shadow test can then compare with the other copy."""
    rng = np.random.default_rng(5)
    floor = np.c_[rng.uniform(0, 4, (3000, 2)), rng.normal(-0.35, 0.003, 3000)]
    yz = np.c_[rng.uniform(0, 4, 3000), rng.uniform(-0.35, 2.2, 3000)]
    wallp = np.c_[3.0 + np.tan(np.radians(5.0)) * yz[:, 1] + rng.normal(0, 0.003, 3000), yz]
    kw = dict(distance_m=0.02, min_share=0.05, cell_m=0.1)
    snapped = detect_planes(np.r_[floor, wallp], **detect_kw(snap_deg=CFG.snap_deg, **kw))
    wall = next(p for p in snapped if abs(p.normal[0]) > 0.9)
    floor_s = next(p for p in snapped if abs(p.normal[2]) > 0.9)
    assert wall.normal @ floor_s.normal == pytest.approx(0.0, abs=1e-9)  # upright


def _ceiling_cloud(rng, n_ceiling=400, sigma=0.01, above=0):
    """A room's thinned cloud: a large floor (z = -0.35), two walls, a desk's underside at
    0.35 m (normals down), and only ``n_ceiling`` points of the ceiling at 2.25 m, seen in
    one corner; ``above`` stray points higher up."""
    floor = np.c_[rng.uniform(-3, 3, (20000, 2)), rng.normal(-0.35, 0.003, 20000)]
    wall_x = np.c_[np.full(8000, 3.0), rng.uniform(-2.5, 2.5, 8000), rng.uniform(-0.35, 1.5, 8000)]
    desk = np.c_[rng.uniform(-1, 0, (600, 2)), rng.normal(0.35, 0.003, 600)]
    ceil = np.c_[rng.uniform(1.5, 3, (n_ceiling, 2)), rng.normal(2.25, sigma, n_ceiling)]
    stray = np.c_[rng.uniform(-3, 3, (above, 2)), rng.uniform(2.6, 3.5, above)]
    pts = np.r_[floor, wall_x, desk, ceil, stray]
    up, side = np.array([0.0, 0.0, 1.0]), np.array([-1.0, 0.0, 0.0])
    nrm = np.r_[np.tile(up, (20000, 1)), np.tile(side, (8000, 1)), np.tile(-up, (600, 1)),
                np.tile(-up, (n_ceiling, 1)), np.tile(-up, (above, 1))]  # fmt: skip
    return pts, nrm


def test_the_ceiling_is_found_from_few_points_and_spans_the_floor():
    """400 noisy ceiling points in a cloud of 29,000 are too few a share for RANSAC; the
    ceiling search finds them at the highest dense height (not the desk's underside), at
    the peak of their noise, and widens the ceiling to the floor's extent."""
    from scenebot.dense.planes.ceiling import find_ceiling
    from scenebot.dense.planes.extents import span_floor

    rng = np.random.default_rng(5)
    pts, nrm = _ceiling_cloud(rng, sigma=0.015)
    planes = detect_planes(
        pts, normals=nrm, **detect_kw(distance_m=0.015, min_share=0.02, cell_m=0.1)
    )
    assert not any(abs(p.normal[2]) > 0.9 and -p.offset * p.normal[2] > 2 for p in planes)
    cams = np.c_[rng.uniform(-2, 2, (20, 2)), np.zeros(20)]
    ceiling = find_ceiling(pts, nrm, planes, cams, 0.015, 30.0, 100, 0.1, 3, 2)
    assert ceiling is not None
    assert -ceiling.offset / ceiling.normal[2] == pytest.approx(2.25, abs=0.006)
    middle = np.array([[0.0, 0.0, 2.25]])
    assert not ceiling.inside(middle)[0]  # its own points: one corner only
    floor = next(p for p in planes if abs(p.normal[2]) > 0.9 and p.inliers > 10000)
    span_floor(ceiling, floor)
    assert ceiling.inside(middle)[0] and ceiling.inside(np.array([[-2.5, -2.5, 2.25]]))[0]
    assert not ceiling.inside(np.array([[5.0, 5.0, 2.25]]))[0]


def test_no_ceiling_without_its_points_or_with_depth_above_it():
    from scenebot.dense.planes.ceiling import find_ceiling

    rng = np.random.default_rng(6)
    cams = np.zeros((5, 3))
    for n_ceiling, above in ((0, 0), (40, 0), (400, 300)):
        pts, nrm = _ceiling_cloud(rng, n_ceiling=n_ceiling, above=above)
        planes = detect_planes(
            pts, normals=nrm, **detect_kw(distance_m=0.015, min_share=0.02, cell_m=0.1)
        )
        # (the desk underside, below it all, is never taken for the ceiling)
        assert find_ceiling(pts, nrm, planes, cams, 0.015, 30.0, 100, 0.1, 3, 2) is None


def test_a_ceiling_of_50_points_is_found_and_a_smear_of_as_many_is_not():
    """Office campaigns measured about 429, 100 and 55 voxel points on their ceilings; 50
    are found by default (``plane_fill.ceiling_min_points`` and the peak test), 15 are not,
    and 300 stray points smeared over 30 cm of height (as many in any 3 cm as a ceiling of
    30, but no surface) are not either; the desk below with the walls measured above it is
    never the ceiling."""
    from scenebot.dense.planes.ceiling import find_ceiling

    cfg = PlaneFillConfig()
    cams = np.zeros((5, 3))
    for n_ceiling, sigma, found in ((50, 0.005, True), (15, 0.005, False), (300, 0.1, False)):
        pts, nrm = _ceiling_cloud(np.random.default_rng(7), n_ceiling=n_ceiling, sigma=sigma)
        planes = detect_planes(
            pts, normals=nrm, **detect_kw(distance_m=0.015, min_share=0.02, cell_m=0.1)
        )
        ceiling = find_ceiling(pts, nrm, planes, cams, 0.015, 30.0, cfg.ceiling_min_points,
                               0.1, 3, 2)  # fmt: skip
        assert (ceiling is not None) is found, (n_ceiling, sigma)
        if found:
            assert -ceiling.offset / ceiling.normal[2] == pytest.approx(2.25, abs=0.005)


def test_of_two_shadow_planes_with_as_many_views_the_one_with_fewer_points_goes():
    from scenebot.dense.planes.phantoms import shadow_planes

    wall_pts = backproject(wall(3.0), K, R, T).reshape(-1, 3)
    shadow_pts = backproject(wall(2.97), K, R, T).reshape(-1, 3)[::3]
    planes = detect_planes(
        np.r_[wall_pts, shadow_pts], **detect_kw(distance_m=0.01, min_share=0.05)
    )
    assert len(planes) == 2
    depth = [round(-p.offset / p.normal[2], 2) for p in planes]
    why = shadow_planes(
        planes, np.array([50, 50]), max_gap_m=0.1, max_angle_deg=CFG.merge_angle_deg
    )
    assert [depth[j] for j in why] == [2.97]


def test_of_two_shadow_planes_the_views_prefer_the_one_holding_their_points():
    """A plane 4 cm in front of the wall with more points than the wall (RANSAC found it in
    a denser sample) and as many views supporting both (each measured a strip of it, as a
    tilted plane crossing the wall is near some of every view's points): most of each view's
    points lie on the wall, so the views prefer the wall and the other plane goes, whatever
    its points and support."""
    from scenebot.dense.planes.phantoms import shadow_planes, view_preferences

    wall_pts = backproject(wall(3.0), K, R, T).reshape(-1, 3)[::3]
    shadow_pts = backproject(wall(2.96), K, R, T).reshape(-1, 3)
    planes = detect_planes(
        np.r_[wall_pts, shadow_pts], **detect_kw(distance_m=0.01, min_share=0.05)
    )
    assert len(planes) == 2
    depth = [round(-p.offset / p.normal[2], 2) for p in planes]
    wall_j = depth.index(3.0)
    assert planes[wall_j].inliers < planes[1 - wall_j].inliers
    prefer = np.zeros((2, 2), np.int64)
    for k in range(5):  # five views, each measuring most of the wall at 3 m, a strip at 2.96
        d = wall(3.0)
        d[:, : d.shape[1] * (k + 1) // 12] = 2.96
        on, _, _ = plane_evidence(d, K, R, T, planes, distance_m=0.02, rel_distance=0.0)
        assert (on >= CFG.support_min_points).all()  # every view supports both planes
        prefer += view_preferences(on, CFG.support_min_points)
    assert prefer[wall_j, 1 - wall_j] == 5 and prefer[1 - wall_j, wall_j] == 0
    kw = {"max_gap_m": 0.1, "max_angle_deg": CFG.merge_angle_deg}
    why = shadow_planes(planes, np.array([5, 5]), prefer=prefer, **kw)
    assert [depth[j] for j in why] == [2.96]
    assert "5 on the other" in why[1 - wall_j]
    # without the views' votes the one with more points would have stayed
    assert [depth[j] for j in shadow_planes(planes, np.array([5, 5]), **kw)] == [3.0]


def test_an_object_face_the_view_sees_through_neither_culls_nor_fills_it():
    """A box face's plane (no boundary) whose extent reaches across this view at 1 m, where
    the view measured the wall at 3 m through it: the face is wrong here (the camera stands
    beside the box), so the wall's depth is kept, not culled."""
    d = wall()
    face = detect_planes(backproject(wall(1.0), K, R, T).reshape(-1, 3),
                         **detect_kw(distance_m=0.01, min_share=0.05))  # fmt: skip
    assert len(face) == 1 and not face[0].boundary
    kept, _, _, culled = fill_view(
        d, NORMAL, K, R, T, face, (0.5, 10.0), **fill_kw(bounding_planes=True)
    )
    assert culled == 0 and np.array_equal(kept, d)
    _, _, _, culled = fill_view(d, NORMAL, K, R, T, face, (0.5, 10.0),
                                **fill_kw(bounding_planes=True, max_seen_through=None))  # fmt: skip
    assert culled == d.size  # without the check the whole view is culled


def test_any_boundary_fills_a_plain_ceiling_above_the_wall():
    """The wall z = 3 m is measured only in its lower half; above it, the plain wall and then
    the plain ceiling (y = -1 m, camera y down) have no depth, and no measured neighbour lies
    on the ceiling. Taking any boundary plane the ray meets first fills the ceiling rows with
    the ceiling; taking only the neighbours' planes leaves them empty."""
    v = np.mgrid[0:H, 0:W][0] + 0.5
    ray_y = (v - K[1, 2]) / K[1, 1]
    with np.errstate(divide="ignore"):
        ceil_z = np.where(ray_y < 0, -1.0 / ray_y, np.inf)
    truth = np.minimum(ceil_z, 3.0).astype(np.float32)
    planes = detect_planes(backproject(truth, K, R, T).reshape(-1, 3),
                           **detect_kw(distance_m=0.01, min_share=0.05))  # fmt: skip
    assert len(planes) == 2
    for p in planes:
        p.boundary = True
    d = truth.copy()
    d[:70] = 0  # plain above row 70 (the ceiling line is at row 27)
    kw = dict(bounding_planes=True, max_seen_through=None)
    nb, _, _, _ = fill_view(d, NORMAL, K, R, T, planes, (0.2, 10.0), **fill_kw(**kw))
    anyb, _, _, _ = fill_view(
        d, NORMAL, K, R, T, planes, (0.2, 10.0), **fill_kw(any_boundary=True, **kw)
    )
    rows = slice(5, 22)  # the ceiling, away from its line with the wall
    assert np.all(nb[rows] == 0)
    assert (anyb[rows] > 0).mean() > 0.9
    got = anyb[rows] > 0
    assert np.allclose(anyb[rows][got], truth[rows][got], rtol=1e-3)
    assert np.allclose(anyb[30:70][anyb[30:70] > 0], 3.0, atol=1e-3)  # the wall stays the wall


def test_a_second_pass_spreads_a_wall_fill_its_first_pass_could_not_reach():
    """A wall measured only in a band at the bottom: cells far above it find measured depth
    in too few directions in the first pass; the second counts the first pass's fill."""
    d = wall()
    d[:90] = 0
    planes = planes_of(wall())
    planes[0].boundary = True
    one, n1, f1, _ = fill_view(
        d, NORMAL, K, R, T, planes, (0.5, 10.0), **fill_kw(bounding_planes=True)
    )
    two, _, f2, _ = fill_view(
        one, n1, K, R, T, planes, (0.5, 10.0), **fill_kw(bounding_planes=True)
    )
    assert f1 > 0 and f2 > 0
    assert (two > 0).sum() == (d > 0).sum() + f1 + f2
    assert np.allclose(two[two > 0], 3.0, atol=1e-3)
    cache: dict = {}  # the passes reuse the rays and plane hits: same result
    one_c, n1_c, _, _ = fill_view(d, NORMAL, K, R, T, planes, (0.5, 10.0),
                                  **fill_kw(bounding_planes=True), cache=cache)  # fmt: skip
    assert "hits" in cache
    two_c, _, _, _ = fill_view(one_c, n1_c, K, R, T, planes, (0.5, 10.0),
                               **fill_kw(bounding_planes=True), cache=cache)  # fmt: skip
    assert np.array_equal(one_c, one) and np.array_equal(two_c, two)


def test_fill_behind_a_surface_other_views_measured_is_emptied():
    """The wall fill spread across a plain box face 1 m before it; other views measured the
    box's texture (the cloud): the fill behind it is emptied, the rest kept; a single stray
    point does not empty anything."""
    from scenebot.dense.planes.vetoes import occluded_fill

    d = wall()
    filled = np.ones_like(d, bool)
    rng = np.random.default_rng(7)
    box = np.c_[rng.uniform(-0.5, 0.5, (4000, 2)), np.full(4000, 2.0)]  # x, y at z = 2 m
    bad = occluded_fill(d, filled, K, R, T, box, **OCCLUSION)
    v, u = np.mgrid[0:H, 0:W] + 0.5
    inside = (np.abs((u - W / 2) / F * 2.0) < 0.45) & (np.abs((v - H / 2) / F * 2.0) < 0.45)
    outside = (np.abs((u - W / 2) / F * 2.0) > 0.6) | (np.abs((v - H / 2) / F * 2.0) > 0.6)
    assert bad[inside].all() and not bad[outside].any()
    stray = np.array([[0.0, 0.0, 2.0]])
    assert not occluded_fill(d, filled, K, R, T, stray, **OCCLUSION).any()
    assert not occluded_fill(d, ~filled, K, R, T, box, **OCCLUSION).any()  # measured pixels stay


def test_the_floor_before_the_camera_is_filled_nearer_than_the_views_depth_range():
    """The view's depth range comes from its sparse points (the stereo's sampling range);
    the plain floor just before the camera lies nearer than any of them and is filled."""
    from scenebot.dense.planes.extents import carved_hulls

    truth = _room_view()
    d = np.zeros_like(truth)
    d[:8], d[-8:], d[:, :8], d[:, -8:] = truth[:8], truth[-8:], truth[:, :8], truth[:, -8:]
    planes = planes_of(d)
    for pl, ext in zip(planes, carved_hulls(planes, [(d, K, R, T)], **HULLS), strict=True):
        pl.occupied = ext
    near = (d == 0) & (truth < 1.5)
    assert near.sum() > 500
    fd, _, _, _ = fill_view(
        d, NORMAL, K, R, T, planes, (1.5, 10.0), **fill_kw(bounding_planes=True)
    )
    assert (fd[near] > 0).mean() > 0.8
    assert np.allclose(fd[near][fd[near] > 0], truth[near][fd[near] > 0], rtol=1e-3)


def _box_observations(rng, n_box=60, n_wall=120):
    """SfM observations of a view of the wall at 3 m with a box at 1 m covering the
    central third of the image: (uv (N, 2), z (N,)), and the box's pixel mask."""
    lo, hi = (W / 3 + 3, H / 3 + 3), (2 * W / 3 - 3, 2 * H / 3 - 3)
    box_uv = rng.uniform(lo, hi, (n_box, 2))
    wall_uv = rng.uniform([0, 0], [W, H], (4 * n_wall, 2))
    in_box = np.all(np.abs(wall_uv - (W / 2, H / 2)) < (W / 6 + 8, H / 6 + 8), axis=1)
    wall_uv = wall_uv[~in_box][:n_wall]
    uv = np.r_[box_uv, wall_uv]
    z = np.r_[np.full(len(box_uv), 1.0), np.full(len(wall_uv), 3.0)]
    v, u = np.mgrid[0:H, 0:W] + 0.5
    mask = (np.abs(u - W / 2) < W / 6) & (np.abs(v - H / 2) < H / 6)
    return uv, z, mask


def test_fill_that_the_views_own_sfm_points_contradict_is_emptied():
    """The wall fill (3 m) painted across a box at 1 m that stereo missed; the view's own
    SfM points on the box lie 2 m before the fill: the fill between them is emptied, the
    wall's fill beyond the box is kept, and measured pixels are never touched."""
    from scenebot.dense.planes.vetoes import sparse_contradicted_fill

    rng = np.random.default_rng(3)
    uv, z, box = _box_observations(rng)
    d = wall()
    filled = np.ones_like(d, bool)
    bad = sparse_contradicted_fill(d, filled, uv, z, max_edge_px=EDGE)
    v, u = np.mgrid[0:H, 0:W] + 0.5
    inner = (np.abs(u - W / 2) < W / 6 - 8) & (np.abs(v - H / 2) < H / 6 - 8)
    assert bad[inner].mean() > 0.95 and bad[box].mean() > 0.6  # between its features
    far = (np.abs(u - W / 2) > W / 6 + 6) | (np.abs(v - H / 2) > H / 6 + 6)
    assert not bad[far].any()  # the wall around it keeps its fill
    assert not sparse_contradicted_fill(
        d, ~filled, uv, z, max_edge_px=EDGE
    ).any()  # measured pixels stay


def test_sfm_points_that_agree_with_the_fill_or_one_stray_point_veto_nothing():
    """Every observation on the filled wall at its depth (within 5%): nothing is emptied;
    a single point off the fill empties only its own few pixels."""
    from scenebot.dense.planes.vetoes import sparse_contradicted_fill

    rng = np.random.default_rng(4)
    uv = rng.uniform([0, 0], [W, H], (200, 2))
    d = wall()
    filled = np.ones_like(d, bool)
    z = np.full(len(uv), 3.0) * rng.uniform(0.98, 1.02, len(uv))
    assert not sparse_contradicted_fill(d, filled, uv, z, max_edge_px=EDGE).any()
    z[0] = 1.0
    assert 0 < sparse_contradicted_fill(d, filled, uv, z, max_edge_px=EDGE).sum() <= 49


def test_walls_rise_to_the_ceiling_but_a_doorway_stays_open():
    """A wall measured up to 2.2 m under a ceiling at 2.5 m: every column rises to the
    ceiling; a doorway below its lintel and a column with no cell at all stay empty; a
    floor-parallel plane does not rise."""
    from scenebot.dense.planes.extents import span_to_ceiling
    from scenebot.dense.planes.geometry import Plane

    cell = 0.1
    basis = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -1.0]])  # along the wall, down
    occ = np.ones((40, 22), bool)  # y 0..4 m, z 2.2 (row 0) .. 0 m
    occ[10:18, 2:] = False  # a doorway up to 2.0 m, its lintel above
    occ[30, :] = False  # an opening to the ceiling
    wall = Plane(np.array([1.0, 0, 0]), -3.0, basis, np.array([3.0, 0, 0]), cell,
                 np.array([0.0, -2.2]), occ.copy(), 1000, boundary=True)  # fmt: skip
    ceiling = Plane(np.array([0, 0, 1.0]), -2.5, np.eye(3)[:2], np.array([0, 0, 2.5]), cell,
                    np.zeros(2), np.ones((1, 1), bool), 80, boundary=True)  # fmt: skip
    added = span_to_ceiling(wall, ceiling, max_rise_m=CFG.walls_to_ceiling_m)
    assert added > 0

    def on(y, z):
        return bool(wall.inside(np.array([[3.0, y, z]]))[0])

    for y in (0.05, 0.55, 1.25, 2.45, 3.95):
        assert on(y, 2.45) and on(y, 2.3)  # risen to the ceiling
        assert not on(y, 2.6)  # not past it
    assert not on(1.45, 1.0) and not on(1.45, 0.1)  # the doorway
    assert not on(3.05, 2.45) and not on(3.05, 1.0)  # the opening
    assert on(0.55, 1.0)  # the old cells kept
    floor = Plane(np.array([0, 0, 1.0]), 0.0, np.eye(3)[:2], np.zeros(3), cell, np.zeros(2),
                  np.ones((5, 5), bool), 500, boundary=True)  # fmt: skip
    assert span_to_ceiling(floor, ceiling, max_rise_m=CFG.walls_to_ceiling_m) == 0


def test_the_ceiling_reaches_the_walls_it_meets():
    """A ceiling spanned from the floor stops 0.5 m short of a wall (furniture on the floor
    along it); the wall's top edge widens the ceiling to the wall, not past it."""
    from scenebot.dense.planes.extents import span_walls
    from scenebot.dense.planes.geometry import Plane

    cell = 0.1
    ceiling = Plane(np.array([0, 0, 1.0]), -2.5, np.eye(3)[:2], np.array([0, 0, 2.5]), cell,
                    np.array([0.0, 0.0]), np.ones((25, 40), bool), 80, boundary=True)  # fmt: skip
    # x 0..2.5 m (rows), y 0..4 m (columns); the wall at x = 3.0, 0.5 m beyond
    occ = np.ones((40, 26), bool)  # along y, z 2.55 .. 0 m
    wall = Plane(np.array([1.0, 0, 0]), -3.0, np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]),
                 np.array([3.0, 0, 0]), cell, np.array([0.0, -2.55]), occ, 1000,
                 boundary=True)  # fmt: skip
    assert span_walls(ceiling, [wall]) > 0

    def on(x, y):
        return bool(ceiling.inside(np.array([[x, y, 2.5]]))[0])

    for y in (0.65, 2.05, 3.35):  # (an open end of the strip is left to the next wall)
        assert on(1.0, y) and on(2.75, y) and on(2.95, y)  # the strip along the wall
        assert not on(3.35, y)  # not past the wall


@pytest.mark.parametrize("nz", [-1.0, 1.0])
def test_the_floor_reaches_the_walls_that_stand_on_it(nz):
    """The floor's extent ends 0.5 m short of a wall (its corner seen only at grazing
    angles); where the wall's cells reach the floor the floor widens to it, where the wall's
    lowest cells are 1 m up (something stood in front of it) it does not. Either sign of the
    floor's normal: the side away from the cameras decides."""
    from scenebot.dense.planes.extents import span_walls
    from scenebot.dense.planes.geometry import Plane

    cell = 0.1
    occ = np.zeros((40, 40), bool)
    occ[:35] = True  # x 0..3.5 m (rows), y 0..4 m (columns)
    floor = Plane(np.array([0, 0, nz]), 0.0, np.eye(3)[:2], np.zeros(3), cell,
                  np.array([0.0, 0.0]), occ, 5000, boundary=True)  # fmt: skip
    wocc = np.ones((40, 26), bool)  # the wall at x = 4: rows along y, columns z 2.5 .. 0 m
    wocc[20:, 16:] = False  # y 2..4 m: nothing measured below z = 1 m
    wall = Plane(np.array([1.0, 0, 0]), -4.0, np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]),
                 np.array([4.0, 0, 0]), cell, np.array([0.0, -2.55]), wocc, 1000,
                 boundary=True)  # fmt: skip
    cams = np.array([[1.0, 1.0, 0.35], [2.0, 3.0, 0.35]])
    assert span_walls(floor, [wall], centres=cams) > 0

    def on(x, y):
        return bool(floor.inside(np.array([[x, y, 0.0]]))[0])

    for y in (0.35, 1.05, 1.65):
        assert on(3.75, y) and on(3.95, y) and not on(4.35, y)
    for y in (2.55, 3.45):
        assert on(3.45, y) and not on(3.75, y)
