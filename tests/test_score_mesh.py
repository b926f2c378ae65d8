"""Mesh, free space and candidates of a synthetic room with a known geometry."""

import itertools
import json
import os

import numpy as np
import pytest

os.environ.setdefault("TI_SKIP_VERSION_CHECK", "ON")

from scenebot.artifacts.freespace import FreeSpace, FreeSpaceError, point_segment_distance
from scenebot.artifacts.mesh import MeshError, check_mesh, read_mesh
from scenebot.mesh.config import MeshConfig
from scenebot.mesh.freespace import compute_freespace, cut_segments
from scenebot.mesh.poisson import build_mesh
from scenebot.mesh.stage import MeshInputs, MeshOutputs
from scenebot.mesh.stage import run as run_mesh
from scenebot.score.candidates import sample_candidates
from scenebot.testing import score as syn

ROOM = (6.0, 4.0)
RINGS = [[-1.5, -0.5], [0.0, 0.5], [1.5, -1.0], [-0.5, -1.2], [-2.0, 1.0]]


@pytest.fixture(scope="module")
def mapped_room(tmp_path_factory):
    """A synthetic COLMAP map of the room and the mesh stage's outputs."""
    root = tmp_path_factory.mktemp("score") / "office" / "round_001"
    V, F = syn.room(size=ROOM, cell_m=0.5)
    R, t, poses = syn.ring_sources(RINGS, 12)
    K = syn.default_intrinsics()
    rng = np.random.default_rng(1)
    pts, _ = syn.sample_surface(V, F, 12000, rng)
    seen = syn.visible_mask(V, F, R, t, K, pts)
    syn.write_colmap_model(root / "sfm", K, R, t, pts, seen, rng)
    out = MeshOutputs(
        root / "mesh.ply", root / "freespace.json", root / "freespace.npz", root / "freespace.png"
    )
    summary = run_mesh(MeshConfig(), MeshInputs(root / "sfm"), out)
    return {"root": root, "V": V, "F": F, "poses": poses, "out": out, "summary": summary}


def test_mesh_lies_on_the_true_surfaces(mapped_room):
    import open3d as o3d

    Vm, Fm = read_mesh(mapped_room["out"].mesh_ply)
    assert len(Fm) > 1000
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(mapped_room["V"].astype(np.float32)),
        o3d.core.Tensor(mapped_room["F"].astype(np.uint32)),
    )
    d = scene.compute_distance(o3d.core.Tensor(Vm.astype(np.float32))).numpy()
    assert np.median(d) < 0.03
    assert np.quantile(d, 0.9) < 0.10


def test_freespace_matches_the_room(mapped_room):
    fs = FreeSpace.load(mapped_room["out"].freespace_npz)
    r = MeshConfig().robot_radius_m
    assert fs.closed
    # all cameras stand in free space (they are >= 0.5 m from every wall)
    assert fs.contains(mapped_room["poses"][:, :2]).all()
    # the free area is the room shrunk by the radius, minus the furniture grown by the radius
    room = (ROOM[0] - 2 * r) * (ROOM[1] - 2 * r)
    table = (1.0 + 2 * r) * (0.8 + 2 * r)
    cabinet = 0.7 * 0.6 + 0.6 * (0.7 + 0.6 + 2 * r) * r  # against the room corner
    expected = room - table - cabinet
    assert abs(fs.area_m2 - expected) / expected < 0.12
    doc = json.loads(mapped_room["out"].freespace_json.read_text())
    assert doc["round"] == "round_001" and doc["type"] == "MultiPolygon"
    assert doc["coordinates"] and len(doc["coordinates"][0][0]) >= 4
    # the polygon area (shoelace) agrees with the raster area
    area = 0.0
    for poly in doc["coordinates"]:
        for k, ring in enumerate(poly):
            x, y = np.array(ring).T
            a = 0.5 * abs(np.dot(x[:-1], y[1:]) - np.dot(x[1:], y[:-1]))
            area += a if k == 0 else -a
    assert abs(area - fs.area_m2) / fs.area_m2 < 0.05
    assert mapped_room["out"].freespace_png.stat().st_size > 1000


def test_candidates_keep_the_robot_radius(mapped_room):
    fs = FreeSpace.load(mapped_room["out"].freespace_npz)
    poses = sample_candidates(fs, 500, np.random.default_rng(0), "round_001")
    assert poses.shape == (500, 3)
    Vm, Fm = read_mesh(mapped_room["out"].mesh_ply)
    d = point_segment_distance(poses[:, :2], cut_segments(Vm, Fm, 0.0))
    assert d.min() >= MeshConfig().robot_radius_m
    assert np.all(np.abs(poses[:, 2]) <= np.pi)
    # they spread over the room
    assert np.ptp(poses[:, 0]) > 4.0 and np.ptp(poses[:, 1]) > 2.5


def test_cut_of_a_box_gives_its_outline():
    V, F = syn.box_mesh((-1, -2, -0.5), (3, 1, 0.5), cell_m=0.4)
    seg = cut_segments(V, F, 0.0)
    p = seg.reshape(-1, 2)
    on_x = np.isclose(p[:, 0], -1) | np.isclose(p[:, 0], 3)
    on_y = np.isclose(p[:, 1], -2) | np.isclose(p[:, 1], 1)
    assert np.all(on_x | on_y)
    length = np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1).sum()
    assert np.isclose(length, 2 * (4 + 3))


def test_empty_and_degenerate_meshes_are_named():
    with pytest.raises(MeshError, match=r"round_004.*empty"):
        check_mesh(np.zeros((0, 3)), np.zeros((0, 3), int), "round_004 mesh.ply")
    flat = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0.0]])
    with pytest.raises(MeshError, match="round_004"):
        check_mesh(flat, np.array([[0, 1, 2]]), "round_004 mesh.ply")


def test_too_few_points_is_named():
    rng = np.random.default_rng(0)
    xyz = rng.normal(size=(10, 3))
    with pytest.raises(MeshError, match=r"round_002.*mesh\.min_points"):
        build_mesh(xyz, xyz, np.full(10, 3), MeshConfig(), "round_002")


def test_empty_freespace_and_zero_candidates_are_named():
    V, F = syn.room(size=(2.0, 2.0), cell_m=0.5, furniture=False)
    cams = np.array([[0.0, 0.0]])
    with pytest.raises(FreeSpaceError, match=r"round_003.*robot_radius_m"):
        compute_freespace(V, F, cams, 1.2, [0.0], 0.02, "round_003")
    fs = compute_freespace(V, F, cams, 0.15, [0.0], 0.02, "round_003")
    with pytest.raises(FreeSpaceError, match=r"round_003.*n_candidates"):
        sample_candidates(fs, 0, np.random.default_rng(0), "round_003")
    empty = FreeSpace(np.zeros_like(fs.mask), fs.origin, fs.resolution, fs.segments, 0.15)
    with pytest.raises(FreeSpaceError, match=r"round_003.*empty"):
        sample_candidates(empty, 10, np.random.default_rng(0), "round_003")


def test_points_hundreds_of_metres_out_are_left_out_of_the_mesh(tmp_path, caplog):
    """A few triangulations of nearly parallel rays land hundreds of metres away; they must
    not stretch the mesh or the free-space raster (that raster would not fit in memory)."""
    from scenebot.artifacts.freespace import FreeSpaceError

    V, F = syn.room(size=ROOM, cell_m=0.5)
    R, t, _ = syn.ring_sources(RINGS, 12)
    K = syn.default_intrinsics()
    rng = np.random.default_rng(2)
    pts, _ = syn.sample_surface(V, F, 6000, rng)
    seen = syn.visible_mask(V, F, R, t, K, pts)
    c0 = -R[0].T @ t[0]
    far = np.array([c0 + d * R[0][2] for d in (60.0, 300.0, 840.0)])  # along camera 0's axis
    seen_far = np.zeros((len(R), len(far)), bool)
    seen_far[[0, 1]] = True
    sfm = tmp_path / "office" / "round_001" / "sfm"
    syn.write_colmap_model(sfm, K, R, t, np.r_[pts, far], np.c_[seen, seen_far], rng)

    def outputs(name):
        d = tmp_path / name
        d.mkdir()
        return MeshOutputs(d / "mesh.ply", d / "fs.json", d / "fs.npz", None)

    with caplog.at_level("WARNING"):
        summary = run_mesh(MeshConfig(), MeshInputs(sfm), outputs("kept"))
    assert "3 3D point(s) farther than mesh.max_point_range_m" in caplog.text
    Vm, _ = read_mesh(tmp_path / "kept" / "mesh.ply")
    assert np.all(np.abs(Vm[:, :2]) < np.array(ROOM) / 2 + 0.5)
    assert summary["free_area_m2"] < ROOM[0] * ROOM[1]
    # kept, they swamp Poisson's octree (the room's mesh comes out empty) or the raster
    with pytest.raises((FreeSpaceError, MeshError)):
        run_mesh(MeshConfig(max_point_range_m=1e4), MeshInputs(sfm), outputs("all"))


def _walls(polyline, z=(-0.5, 2.0)):
    """Vertical wall quads along a 2D polyline: (V, F)."""
    V, F = [], []
    for (x0, y0), (x1, y1) in itertools.pairwise(polyline):
        k = len(V)
        V += [[x0, y0, z[0]], [x1, y1, z[0]], [x1, y1, z[1]], [x0, y0, z[1]]]
        F += [[k, k + 1, k + 2], [k, k + 2, k + 3]]
    return np.array(V, float), np.array(F, int)


def test_free_space_ends_where_no_camera_saw_across():
    """A room whose east wall has a 1.5 m hole (a plain whiteboard the map never measured),
    its Poisson surface bulging out through it: the cut shows free space outside the room,
    which the cameras' lines of sight to the points they observed do not cross; with them
    the free space is the room's."""
    parts = [
        _walls([(3, 0.75), (3, 2), (-3, 2), (-3, -2), (3, -2), (3, -0.75)]),  # the room
        _walls([(3, 0.75), (5, 1.5), (5, -1.5), (3, -0.75)]),  # the bulge beyond the hole
    ]
    V = np.concatenate([parts[0][0], parts[1][0]])
    F = np.concatenate([parts[0][1], parts[1][1] + len(parts[0][0])])
    cams = np.array([[0.0, 0.0], [-1.5, 1.0], [1.0, -1.0]])
    rng = np.random.default_rng(2)
    t = rng.uniform(0, 1, 400)  # observed points on the room's measured walls
    walls = np.r_[np.c_[np.full(100, -3.0), -2 + 4 * t[:100]], np.c_[-3 + 6 * t[100:200],
                  np.full(100, 2.0)], np.c_[-3 + 6 * t[200:300], np.full(100, -2.0)],
                  np.c_[np.full(50, 3.0), 0.75 + 1.25 * t[300:350]],
                  np.c_[np.full(50, 3.0), -2 + 1.25 * t[350:]]]  # fmt: skip
    rays = np.stack([np.repeat(cams, len(walls), 0), np.tile(walls, (len(cams), 1))], 1)
    old = compute_freespace(V, F, cams, 0.15, [0.0], 0.05, "round_001")
    new = compute_freespace(V, F, cams, 0.15, [0.0], 0.05, "round_001", rays=rays)
    outside = np.array([[3.8, 0.0], [4.5, 0.5], [4.5, -0.8]])
    assert old.contains(outside).all()  # the cut alone leaks out of the room
    assert not new.contains(outside).any()
    assert new.contains(cams).all()
    room = (6 - 0.3) * (4 - 0.3)
    assert 0.85 * room < new.area_m2 <= room + 0.1 and old.area_m2 > room + 3.0
