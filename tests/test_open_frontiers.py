"""Open frontiers: where the free space ends at space the map knows nothing about (a doorway
whose far side no photo saw), the goals stage asks for a look across before the score's goals,
and the map is not complete while one is left."""

import json

import numpy as np
import pytest

from scenebot.goals.config import GoalsConfig
from scenebot.goals.frontier import open_boundary, open_frontier_goals
from scenebot.goals.select import goals_document
from scenebot.goals.stage import _apply_open_frontiers, _open_frontiers
from scenebot.mesh.freespace import compute_freespace

RADIUS = 0.2


def _walls(segments_xy):
    """Vertical wall quads (z -0.5 .. 1.5) over 2-D segments: (V, 3), (F, 3)."""
    verts, faces = [], []
    for (x0, y0), (x1, y1) in segments_xy:
        k = len(verts)
        verts += [(x0, y0, -0.5), (x1, y1, -0.5), (x1, y1, 1.5), (x0, y0, 1.5)]
        faces += [(k, k + 1, k + 2), (k, k + 2, k + 3)]
    return np.array(verts, float), np.array(faces, int)


def _room(door: bool, doors: tuple = ((1.0, 1.9),)):
    """A 4 m x 3 m room photographed from inside; with ``door`` 0.9 m doorways in its east
    wall (x = 4, ``doors``: y from, to) to rooms no photo saw (not in the mesh, no point)."""
    ys = [0.0, *(y for d in doors for y in d), 3.0] if door else [0.0, 3.0]
    east = [((4, ys[i]), (4, ys[i + 1])) for i in range(0, len(ys), 2)]
    segs = [((0, 0), (4, 0)), ((4, 3), (0, 3)), ((0, 3), (0, 0)), *east]
    V, F = _walls(segs)
    cams = np.array([[1.0, 1.0], [1.0, 2.0], [2.0, 1.5], [3.0, 1.0], [3.0, 2.0]])
    # the map's lines of sight: every camera to points along the walls it has (none beyond
    # the doorway)
    pts = []
    for (x0, y0), (x1, y1) in segs:
        n = int(np.hypot(x1 - x0, y1 - y0) / 0.05)
        t = np.linspace(0, 1, n + 1)
        pts.append(np.c_[x0 + t * (x1 - x0), y0 + t * (y1 - y0)])
    pts = np.concatenate(pts)
    rays = np.array([[c, p] for c in cams for p in pts], float)
    return compute_freespace(V, F, cams, RADIUS, [0.0], 0.05, "test", rays)


def test_a_doorway_to_an_unseen_room_is_an_open_frontier_looked_through():
    fs = _room(door=True)
    boundary, _ = open_boundary(fs)
    assert boundary.any() and not (boundary & ~fs.mask).any()
    jj, ii = np.nonzero(boundary)
    xy = fs.origin + (np.stack([ii, jj], 1) + 0.5) * fs.resolution
    assert np.all(xy[:, 0] > 3.2) and np.all((xy[:, 1] > 0.9) & (xy[:, 1] < 2.0))  # the door
    goals, _, _ = open_frontier_goals(fs, RADIUS, 1.0, np.zeros((0, 2)), k=5)
    assert len(goals) == 1
    g = goals[0]
    assert 2.7 < g["x"] < 4.2 and abs(g["y"] - 1.45) < 0.25
    assert np.cos(g["theta"]) > 0.9  # looking east, through the doorway
    assert fs.contains(np.array([[g["x"], g["y"]]]))[0]
    assert RADIUS <= g["opening_m"] <= 0.9 + 0.1
    # a place already visited for it: looked across once, not asked again
    again, _, _ = open_frontier_goals(fs, RADIUS, 1.0, np.array([[g["x"], g["y"]]]), 5)
    assert again == []


def test_a_closed_room_has_no_open_frontier():
    fs = _room(door=False)
    boundary, _ = open_boundary(fs)
    assert not boundary.any()
    assert open_frontier_goals(fs, RADIUS, 1.0, np.zeros((0, 2)), 5)[0] == []


def test_unknown_pockets_inside_the_walls_are_not_frontiers():
    """Space no line of sight crossed inside the mapped walls (the shadow of a piece of
    furniture) is the score's to value, whatever its size: only space the mesh does not
    enclose is a frontier."""
    fs = _room(door=False)
    fs.mask[20:40, 30:50] = False  # a 1 m x 1 m hole in the middle no line of sight crossed
    boundary, unknown = open_boundary(fs)
    assert not boundary.any() and not unknown[20:40, 30:50].any()
    with_door = _room(door=True)
    with_door.mask[20:40, 30:50] = False
    boundary, _ = open_boundary(with_door)
    _, ii = np.nonzero(boundary)
    assert boundary.any() and ((ii + 0.5) * 0.05 + with_door.origin[0]).min() > 3.0  # door only


@pytest.mark.parametrize("door", [True, False])
def test_the_map_is_not_complete_while_a_frontier_is_left(door, tmp_path):
    fs = _room(door)
    cfg = GoalsConfig(k=3)
    # the previous round visited nothing; rule 1 says complete (every score below threshold)
    poses = np.array([[1.0, 1.5, 0.0], [2.0, 2.0, 1.0], [3.0, 1.0, 2.0]])
    score = np.array([1.0, 2.0, 3.0])
    doc = goals_document(poses, score, np.array([2, 1]), 10.0, "round_001")
    assert doc["complete"]
    doc["complete_because"] = "best view score 3.0 deg < goals.complete_threshold_deg = 10.0"
    front = _open_frontiers(cfg, fs, None, [])
    _apply_open_frontiers(doc, front, "round_001")
    assert doc["complete"] is (not door)
    ranks = [g["rank"] for g in doc["goals"]]
    assert ranks == list(range(len(ranks)))
    if door:
        assert doc["goals"][0]["frontier"] and doc["goals"][0]["candidate"] is None
        assert "open frontier" in doc["not_complete_because"]
        assert doc["open_frontiers"]["goals"] == 1 and len(doc["goals"]) == 3
        # the next round: this frontier visited, so none is asked for and the map may end
        prev = tmp_path / "goals.json"
        prev.write_text(json.dumps(doc))
        front2 = _open_frontiers(cfg, fs, prev, [])
        assert front2["goals"] == [] and len(front2["visited"]) == 1
    else:
        assert doc["open_frontiers"]["goals"] == 0 and len(doc["goals"]) == 2


def test_goals_abandoned_near_a_doorway_are_not_asked_for_as_frontiers():
    fs = _room(door=True)
    near_door = [{"x": 3.7, "y": 1.45, "theta": 0.0}]
    front = _open_frontiers(GoalsConfig(), fs, None, near_door)
    assert front["goals"] == []


def test_one_goal_per_opening():
    fs = _room(door=True, doors=((0.3, 1.2), (1.8, 2.7)))
    two, _, _ = open_frontier_goals(fs, RADIUS, 1.0, np.zeros((0, 2)), 5)
    assert len(two) == 2 and abs(two[0]["y"] - two[1]["y"]) > 1.0
    assert all(np.cos(g["theta"]) > 0.8 for g in two)
    # goals closer than the look distance are taken for pieces of one opening
    assert len(open_frontier_goals(fs, RADIUS, 3.0, np.zeros((0, 2)), 5)[0]) == 1
