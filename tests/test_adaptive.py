"""Adaptive rounds: photo patterns at goals, goal snapping, the campaign summary, sim state."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from scenebot.campaign import summarize
from scenebot.capture.adaptive import goal_headings, map_end_pose
from scenebot.config import AdaptiveConfig, Config
from scenebot.plan import PlanConfig, build_navgrid
from scenebot.plan.navgrid import snap_to_free
from scenebot.plan.stage import plan_all
from scenebot.robot.base import Pose2D, wrap_angle
from scenebot.robot.sim import read_sim_state, write_sim_state


def test_fan_is_centred_on_the_goal_heading_and_sweeps_once():
    cfg = AdaptiveConfig(pattern="fan", fan_photos=5, fan_step_deg=15)
    hs = goal_headings(1.0, cfg)
    offsets = [math.degrees(h - 1.0) for h in hs]
    assert offsets == pytest.approx([-30, -15, 0, 15, 30])
    assert goal_headings(1.0, AdaptiveConfig(fan_photos=1)) == [1.0]
    even = [math.degrees(h - 1.0) for h in goal_headings(1.0, AdaptiveConfig(fan_photos=4))]
    assert 0.0 in even and len(even) == 4 and sorted(even) == even


def test_circle_covers_every_direction_once():
    hs = goal_headings(0.3, AdaptiveConfig(pattern="circle", circle_photos=12))
    steps = np.diff(np.unwrap(np.array(hs)))
    assert len(hs) == 12 and np.allclose(steps, 2 * math.pi / 12)
    assert hs[0] == pytest.approx(0.3)


def test_camera_mount_is_configured_once_and_follow_inherits_it():
    cfg = Config.model_validate({"sim": {"camera": {"forward_offset_m": 0.2}}})
    assert cfg.follow.camera_forward_m == 0.2
    assert cfg.camera_mount() == (0.2, 0.0)
    own = Config.model_validate(
        {"sim": {"camera": {"forward_offset_m": 0.2}}, "follow": {"camera_forward_m": 0.05}}
    )
    assert own.follow.camera_forward_m == 0.05  # an explicit value is kept
    # the default campaign stays within issue 9's budget of 260 photos
    c = Config()
    assert c.exploration.photos + (c.max_rounds - 1) * c.goals.k * c.adaptive.fan_photos <= 260
    assert Config(max_rounds=2).round_limit() == 2
    photos = Config.model_validate({"robot": "photos", "photos": {"folder": "x"}, "max_rounds": 3})
    assert photos.round_limit() == 1  # a folder of photos is round 0; no robot takes more


def _grid():
    """A 4 m square room with a 1 m pillar in the middle (points on its walls)."""
    rng = np.random.default_rng(0)
    t = rng.uniform(0, 1, 4000)
    walls = np.concatenate(
        [
            np.stack([t * 4, np.zeros_like(t)], 1),
            np.stack([t * 4, np.full_like(t, 4)], 1),
            np.stack([np.zeros_like(t), t * 4], 1),
            np.stack([np.full_like(t, 4), t * 4], 1),
            np.stack([1.5 + t, np.full_like(t, 1.5)], 1),
            np.stack([1.5 + t, np.full_like(t, 2.5)], 1),
            np.stack([np.full_like(t, 1.5), 1.5 + t], 1),
            np.stack([np.full_like(t, 2.5), 1.5 + t], 1),
        ]
    )
    pts = np.column_stack([walls, rng.uniform(0.05, 0.5, len(walls))])
    cfg = PlanConfig(margin_m=0.2)
    return build_navgrid(pts, np.array([[0.0, 0.0], [4.0, 4.0]]), cfg), cfg


def test_a_goal_just_inside_an_obstacle_snaps_to_the_nearest_free_cell():
    grid, _ = _grid()
    inside_wall = np.array([1.55, 2.0])  # just inside the pillar's wall band
    g = grid.geometry
    c = g.cell_of(inside_wall)
    assert grid.lethal[c[0], c[1]]
    snapped = snap_to_free(grid, inside_wall, 0.6)
    assert snapped is not None
    sc = g.cell_of(snapped)
    assert not grid.lethal[sc[0], sc[1]]
    assert np.hypot(*(snapped - inside_wall)) <= 0.6
    assert snap_to_free(grid, np.array([1.5, 2.0]), 0.01) is None  # no free cell near
    free = np.array([0.8, 0.8])
    assert np.allclose(snap_to_free(grid, free, 0.3), free)  # a free goal stays put
    assert snap_to_free(grid, np.array([50.0, 50.0]), 1.0) is None  # outside the grid


def test_plan_all_records_a_snapped_goal_and_plans_to_it():
    grid, cfg = _grid()
    cfg = cfg.model_copy(update={"goal_snap_m": 0.6})
    goal = np.array([1.45, 2.0])  # in the pillar's inflated wall band, on the outside
    c = grid.geometry.cell_of(goal)
    assert grid.lethal[c[0], c[1]]
    paths = plan_all(grid, np.array([0.8, 0.8]), [{"x": goal[0], "y": goal[1]}], cfg)
    p = paths[0]
    assert p["status"] == "ok", p
    assert "snapped_from" in p and p["snap_m"] <= 0.6
    assert np.allclose(p["waypoints"][-1], p["robot_goal"])


def test_sim_state_round_trip(tmp_path):
    class W:
        truth_pose = Pose2D(1.0, 2.0, 0.5)
        t = 12.0

    assert read_sim_state(tmp_path) is None
    write_sim_state(tmp_path, W())
    assert read_sim_state(tmp_path) == Pose2D(1.0, 2.0, 0.5)
    write_sim_state(tmp_path / "nothing", None)  # a real robot leaves no state
    assert not (tmp_path / "nothing").exists()


def _round(root, r, photos, goals_complete, best, events=(), registered=None):
    d = root / f"round_{r:03d}"
    (d / "capture").mkdir(parents=True)
    (d / "sfm").mkdir()
    recs = [{"type": "session", "round": r}]
    recs += [{"type": "photo", "index": i, "image": f"images/r{r:03d}_{i:04d}.jpg"}
             for i in range(photos)]  # fmt: skip
    recs += list(events)
    reached = sum(e.get("event") == "goal_reached" for e in events)
    recs.append({"type": "end", "goals": 2, "reached": reached, "abandoned": 2 - reached,
                 "skipped": 0, "outcomes": []})  # fmt: skip
    (d / "capture" / "log.jsonl").write_text("\n".join(json.dumps(x) for x in recs) + "\n")
    (d / "sfm" / "report.json").write_text(
        json.dumps({"photos": photos, "registered": registered or photos})
    )
    (d / "goals.json").write_text(
        json.dumps({"complete": goals_complete, "best_score_deg": best, "goals": [{}]})
    )


def test_campaign_summary_counts_photos_and_says_why_it_stopped(tmp_path):
    _round(tmp_path, 0, 100, False, 40.0, registered=98)
    _round(tmp_path, 1, 25, True, 8.0, events=[{"type": "event", "event": "goal_reached"}])
    s = summarize(tmp_path, [0, 1], max_rounds=3)
    assert [r["photos_total"] for r in s["rounds"]] == [100, 125]
    assert s["rounds"][0]["registered"] == 98
    assert s["rounds"][1]["goals_visited"]["reached"] == 1
    assert "complete" in s["stopped_because"]
    s2 = summarize(tmp_path, [0], max_rounds=1)
    assert "max_rounds" in s2["stopped_because"] and s2["photos_total"] == 100


def test_goal_error_is_measured_against_the_truth_in_the_map_frame(tmp_path):
    """The evaluation maps the true pose into the map frame with the previous map's
    similarity (here: a 90 degree turn, scale 2, a shift)."""
    yaw = math.pi / 2
    R = [[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0], [0, 0, 1]]
    sim = {"scale": 2.0, "R": R, "t": [1.0, 1.0, 0.35]}

    def world(xy):  # map -> world
        v = 2.0 * np.array(R) @ np.array([xy[0], xy[1], 0.0]) + [1.0, 1.0, 0.35]
        return v

    goal = [0.5, 0.25]
    true_w = world([0.53, 0.25])  # 3 cm off in the map frame
    ev = {"type": "event", "event": "goal_reached", "robot_goal": goal,
          "estimate": {"x": 0.5, "y": 0.25, "theta": 0.0},
          "truth": {"robot": {"x": true_w[0], "y": true_w[1], "theta": yaw}}}  # fmt: skip
    _round(tmp_path, 0, 10, False, 30.0)
    _round(tmp_path, 1, 5, False, 20.0, events=[ev])
    (tmp_path / "round_000" / "sfm" / "accuracy.json").write_text(
        json.dumps(
            {
                "evaluated": 10,
                "similarity": sim,
                "position_error_cm": {"median": 1.0},
                "heading_error_deg": {"median": 0.2},
            }
        )
    )
    s = summarize(tmp_path, [0, 1], max_rounds=2)
    ev1 = s["rounds"][1]["evaluation"]
    assert ev1["goal_true_error_m"]["median"] == pytest.approx(0.03, abs=1e-6)
    assert ev1["goals_truly_within"] == 1
    assert "max_rounds" in s["stopped_because"]


def test_map_end_pose_is_the_robot_behind_the_last_camera(tmp_path):
    pycolmap = pytest.importorskip("pycolmap")
    from scenebot.geometry import look_rotation

    rec = pycolmap.Reconstruction()
    cam = pycolmap.Camera(
        model="PINHOLE", width=64, height=48, params=[50, 50, 32, 24], camera_id=1
    )
    rec.add_camera_with_trivial_rig(cam)
    for i, (c, th) in enumerate([((0, 0, 0), 0.0), ((1.0, 2.0, 0.0), math.pi / 2)]):
        R = look_rotation(th)
        pose = pycolmap.Rigid3d(pycolmap.Rotation3d(R), -R @ np.array(c, float))
        im = pycolmap.Image(name=f"r000_{i:04d}.jpg", camera_id=1, image_id=i + 1)
        rec.add_image_with_trivial_frame(im, pose)
    rec.write_binary(str(tmp_path))
    p = map_end_pose(tmp_path, (0.1, 0.0))
    assert (p.x, p.y) == pytest.approx((1.0, 1.9))
    assert abs(wrap_angle(p.theta - math.pi / 2)) < 1e-9


def test_replanning_moves_a_goal_off_a_freshly_marked_obstacle():
    """A bump near the goal marks a disk over it; the snapping planner still plans, to the
    nearest free cell, instead of giving the goal up."""
    from scenebot.capture.adaptive import SnappingPlanner
    from scenebot.plan.path import GridPlanner, PlanFailure

    grid, _ = _grid()
    start, goal = np.array([0.8, 0.8]), np.array([3.2, 0.8])
    plain = GridPlanner(grid, PlanConfig().simplify_factor)
    snapping = SnappingPlanner(GridPlanner(grid, PlanConfig().simplify_factor), 0.3)
    for p in (plain, snapping):
        p.mark_obstacle(goal + np.array([0.05, 0.0]), 0.15)
    assert isinstance(plain(start, goal), PlanFailure)
    path = snapping(start, goal)
    assert not isinstance(path, PlanFailure)
    end = path.waypoints_xy[-1]
    assert 0.1 < np.hypot(*(end - goal)) <= 0.3


def test_bump_marks_that_wall_the_robot_in_are_forgotten():
    """Bumps mark disks around the robot until no route leaves its spot; the map alone has
    one, so the planner forgets the marks and plans it. A goal the map itself walls off
    stays unreachable (marks or not)."""
    from scenebot.plan.path import GridPlanner, PlanFailure, PlanFailureReason, plan_path

    grid, _ = _grid()
    start, goal = np.array([0.8, 0.8]), np.array([3.2, 3.2])
    planner = GridPlanner(grid, PlanConfig().simplify_factor)
    for a in np.linspace(0, 2 * np.pi, 12, endpoint=False):  # a ring of marks at 0.4 m
        planner.mark_obstacle(start + 0.4 * np.array([np.cos(a), np.sin(a)]), 0.15)
    walled = plan_path(planner.grid, start, goal, planner.simplify_factor)
    assert isinstance(walled, PlanFailure) and walled.reason is PlanFailureReason.NO_ROUTE
    path = planner(start, goal)
    assert not isinstance(path, PlanFailure) and planner.forgotten_marks == 1
    assert np.array_equal(planner.grid.lethal, grid.lethal)  # the marks are gone
    # inside the pillar (walled off by the map itself): no route, nothing forgotten
    planner.mark_obstacle(np.array([0.8, 2.0]), 0.2)
    inside = planner(start, np.array([2.0, 2.0]))
    assert isinstance(inside, PlanFailure) and planner.forgotten_marks == 1


def test_an_abandoned_goal_is_replaced_by_the_next_unused_backup():
    """Goal 0 is reached; goal 1 is given up on the way, and so is its first backup; the
    second backup is reached and photographed; the backup the plan stage already used is
    never tried again; goal 2 is skipped by the plan and costs no backup."""
    from types import SimpleNamespace

    from scenebot.capture.adaptive import unused_backups, visit_goals
    from scenebot.robot.base import Pose2D

    def goal(c):
        return {"candidate": c, "rank": c, "x": float(c), "y": 0.0, "theta": 0.0}

    paths = [
        {"goal": goal(0), "status": "ok", "robot_goal": [0.0, 0.0], "waypoints": []},
        {"goal": goal(1), "status": "ok", "robot_goal": [1.0, 0.0], "waypoints": []},
        {"goal": goal(5), "status": "ok", "robot_goal": [5.0, 0.0], "waypoints": []},  # a backup
        {"goal": goal(2), "status": "no_route", "message": "walled off"},
    ]
    doc = {"goals": [goal(0), goal(1), goal(2), goal(3)], "backups": [goal(5), goal(6), goal(7)]}
    spare = unused_backups(doc, paths)
    assert [b["candidate"] for b in spare] == [6, 7]
    unreachable = {1, 6}
    driven, events = [], []

    def go(g, path, k):
        driven.append((g["candidate"], path is not None))
        ok = g["candidate"] not in unreachable
        return SimpleNamespace(reached=ok, reason="reached" if ok else "5 obstacles met",
                               obstacles=0 if ok else 5, pose=Pose2D(g["x"], 0.0, 0.0),
                               distance_m=0.01, localized_at_goal=True,
                               confirmed_at_goal=True, goal_xy=(g["x"], 0.0))  # fmt: skip

    def event(name, k, g, **fields):
        events.append((name, k, g["candidate"], fields.get("backup_for")))

    outcomes, n = visit_goals(paths, spare, go, lambda g, k, first: 3, event, 3, 60)
    assert driven == [(0, True), (1, True), (6, False), (7, False), (5, True)]
    assert events == [
        ("goal_reached", 0, 0, None),
        ("goal_abandoned", 1, 1, None),
        ("goal_abandoned", 1, 6, 1),
        ("goal_reached", 1, 7, 1),
        ("goal_reached", 2, 5, None),
        ("goal_skipped", 3, 2, None),
    ]
    assert n == 9 and spare == []
    assert [o["status"] for o in outcomes if "backup_for" not in o] == [
        "reached", "abandoned", "reached", "skipped",
    ]  # fmt: skip
    # without backups the abandoned goal stays abandoned and the budget stops the round
    events.clear()
    outcomes, n = visit_goals(paths, [], go, lambda g, k, first: 3, event, 3, 6)
    assert [e[0] for e in events] == ["goal_reached", "goal_abandoned", "goal_reached",
                                      "goal_skipped"]  # fmt: skip
    assert n == 6
