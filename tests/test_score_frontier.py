"""The frontier baseline's goal chooser on a hand-made free space with known visibility."""

import numpy as np

from scenebot.artifacts.freespace import FreeSpace
from scenebot.goals.frontier import frontier_cells, frontier_goals, seen_cells


def room(nx=80, ny=40, res=0.05):
    """A 4 m x 2 m free rectangle (1-cell wall border), walls as cut segments."""
    mask = np.zeros((ny, nx), bool)
    mask[1:-1, 1:-1] = True
    x1, y1 = nx * res, ny * res
    corners = np.array([[0, 0], [x1, 0], [x1, y1], [0, y1], [0, 0]], float)
    segs = np.stack([corners[:-1], corners[1:]], 1)
    return FreeSpace(mask, np.zeros(2), res, segs, 0.1)


def test_a_camera_looking_left_leaves_the_right_half_unseen_and_the_goal_looks_there():
    fs = room()
    seen = seen_cells(fs, np.array([[2.0, 1.0]]), np.array([np.pi]), 90.0, 10.0)
    xs = fs.origin[0] + (np.nonzero(seen)[1] + 0.5) * fs.resolution
    assert seen.any() and xs.max() <= 2.1  # nothing to the right of the camera is seen
    assert not (seen & ~fs.mask).any()
    front = frontier_cells(fs, seen)
    assert front.any() and not (front & ~seen).any()
    goals = frontier_goals(fs, seen, np.array([2.0, 1.0]), k=3, spacing_m=0.5, look_m=1.0)
    assert 1 <= len(goals) <= 3
    g = goals[0]
    assert np.hypot(g["x"] - 2.0, g["y"] - 1.0) < 1.2  # the nearest frontier first
    assert np.cos(g["theta"]) > 0.5  # looking towards the unseen right half
    assert fs.contains(np.array([[g["x"], g["y"]]]))[0]
    pos = np.array([[x["x"], x["y"]] for x in goals])
    d = np.hypot(*(pos[:, None] - pos[None]).transpose(2, 0, 1))
    assert np.all(d[np.triu_indices(len(pos), 1)] > 0.5)  # spaced


def test_walls_block_the_view_and_a_fully_seen_room_has_no_frontier():
    fs = room()
    fs.mask[:, 40] = False  # a wall across the middle (a slit at the top below)
    fs.mask[-3:-1, 40] = True
    seen = seen_cells(fs, np.array([[1.0, 1.0]]), np.array([0.0]), 60.0, 10.0)
    xs = (np.nonzero(seen)[1] + 0.5) * fs.resolution
    assert xs.max() < 2.05  # the wall hides the right half
    everything = fs.mask.copy()
    assert not frontier_cells(fs, everything).any()
    assert frontier_goals(fs, everything, np.array([1.0, 1.0]), 5, 0.5, 1.0) == []
    # a tiny unseen sliver is not a frontier when it is below the minimum area
    sliver = everything.copy()
    sliver[10, 10] = False
    assert frontier_cells(fs, sliver).any()
    assert not frontier_cells(fs, sliver, min_area_m2=0.01).any()
