"""The plan stage end to end on a synthetic COLMAP model."""

from __future__ import annotations

import json

import numpy as np
import pycolmap
import pytest

from scenebot.plan import NavGrid, PlanConfig
from scenebot.plan.stage import PlanInputs, PlanOutputs, read_goals, read_map_geometry, run


@pytest.fixture
def sfm_dir(tmp_path):
    opts = pycolmap.SyntheticDatasetOptions()
    opts.num_points3D = 400
    rec = pycolmap.synthesize_dataset(opts)
    d = tmp_path / "sfm"
    d.mkdir()
    rec.write(str(d))
    return d


def test_plan_stage_writes_grid_paths_and_picture(sfm_dir, tmp_path):
    pts, centres, names = read_map_geometry(sfm_dir)
    assert len(pts) == 400 and len(centres) == len(names) > 0
    lo, hi = centres[:, :2].min(0), centres[:, :2].max(0)
    inside = (lo + hi) / 2
    goals = {
        "goals": [
            {"x": float(inside[0]), "y": float(inside[1]), "theta": 0.5, "score": 1.0},
            [float(hi[0] + 50.0), float(hi[1]), 0.0],  # far outside the grid
            {"x": float(lo[0]), "y": float(lo[1])},
        ]
    }
    gj = tmp_path / "goals.json"
    gj.write_text(json.dumps(goals))
    out = PlanOutputs(tmp_path / "navgrid.npz", tmp_path / "paths.json", tmp_path / "navgrid.png")
    cfg = PlanConfig(obstacle_z_min_m=1e9)  # no obstacles: every in-grid goal is reachable
    doc = run(
        cfg,
        PlanInputs(sfm_dir, gj),
        out,
        start_xy=(float(hi[0]), float(hi[1])),
        camera_offset_m=(0.1, 0.0),
    )
    assert out.navgrid_npz.exists() and out.paths_json.exists() and out.plot_png.exists()
    grid = NavGrid.load(out.navgrid_npz)
    assert max(grid.geometry.shape) == cfg.n_cells
    written = json.loads(out.paths_json.read_text())
    assert written == json.loads(json.dumps(doc))
    p0, p1, p2 = written["paths"]
    # goals are camera poses: the robot axis stops 0.1 m behind the camera centre
    robot_goal = inside - 0.1 * np.array([np.cos(0.5), np.sin(0.5)])
    assert p0["status"] == "ok" and p0["waypoints"][-1] == pytest.approx(list(robot_goal))
    assert p0["robot_goal"] == pytest.approx(list(robot_goal))
    assert p0["waypoints"][0] == pytest.approx([float(hi[0]), float(hi[1])])
    assert p1["status"] == "skipped" and p1["reason"] == "goal_outside_grid"
    # the chain continues from the last reached goal
    assert p2["status"] == "ok" and p2["from"] == pytest.approx(list(robot_goal))
    assert p2["robot_goal"] == pytest.approx([float(lo[0]), float(lo[1])])  # no theta
    assert read_goals(gj)[1] == {"x": goals["goals"][1][0], "y": goals["goals"][1][1], "theta": 0.0}


def test_missing_model_is_a_clear_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="run the sfm stage"):
        read_map_geometry(tmp_path)


def test_a_goal_the_planner_cannot_reach_is_replaced_by_the_next_backup(sfm_dir, tmp_path):
    _, centres, _ = read_map_geometry(sfm_dir)
    lo, hi = centres[:, :2].min(0), centres[:, :2].max(0)
    mid = (lo + hi) / 2
    far = [float(hi[0] + 50.0), float(hi[1])]  # outside the grid: never plannable
    goals = {
        "goals": [{"x": far[0], "y": far[1], "theta": 0.0}, {"x": float(lo[0]), "y": float(lo[1])}],
        "backups": [
            {"x": far[0] + 1.0, "y": far[1], "theta": 0.0},  # no better
            {"x": float(mid[0]), "y": float(mid[1]), "theta": 1.0, "rank": 7},
        ],
    }
    gj = tmp_path / "goals.json"
    gj.write_text(json.dumps(goals))
    out = PlanOutputs(tmp_path / "navgrid.npz", tmp_path / "paths.json")
    doc = run(PlanConfig(obstacle_z_min_m=1e9), PlanInputs(sfm_dir, gj), out, start_xy=tuple(hi))
    p0, p1 = doc["paths"]
    assert p0["status"] == "ok" and p0["goal"]["rank"] == 7
    assert [r["reason"] for r in p0["replaced"]] == ["goal_outside_grid"] * 2
    assert p1["status"] == "ok" and "replaced" not in p1
    # without backups the goal stays, skipped, with its reason
    gj.write_text(json.dumps({"goals": goals["goals"]}))
    doc = run(PlanConfig(obstacle_z_min_m=1e9), PlanInputs(sfm_dir, gj), out, start_xy=tuple(hi))
    assert doc["paths"][0]["status"] == "skipped" and "replaced" not in doc["paths"][0]
