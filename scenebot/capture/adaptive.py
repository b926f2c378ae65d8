"""Adaptive capture, rounds >= 1 (paper IV.B-C): go to the goals of the last map, take photos.

Reads the previous round's folder ``round_{r-1}/``: the map (``sfm/``, for visual
localization), ``goals.json`` (camera poses where a photo is missing), ``paths.json`` (the
planned route) and ``navgrid.npz`` (the grid the follower replans on, marking obstacles the
bumper finds). Writes ``round_{r}/capture/`` like round 0:

* ``images/r{r}_NNNN.jpg``: the photos taken at the goals (read-only, never deleted);
* ``nav/``: the localization photos taken on the way (kept, not part of the map; a re-take
  archives them with everything else, see :func:`scenebot.capture.session.archive_previous`);
* ``session.jsonl`` / ``log.jsonl`` (a hard link; see :mod:`scenebot.capture.session`): photo
  records carry ``odometry``, ``localization`` (the robot pose estimated from that very
  photo, map frame), ``localization_inliers`` and ``goal_index``; events ``follow_start``,
  ``localize``, ``obstacle``, ``replan``, ``follow_end``, ``goal_reached`` /
  ``goal_abandoned`` / ``goal_skipped`` (with the reason; a backup goal driven to in place
  of an abandoned one carries ``backup_for``); in the simulator every record carries
  ``truth`` (evaluation only); ``localize`` events name their photo relative to the capture
  folder (``nav/...``);
* ``trajectory.png`` (a hard link to ``session.png``): the map-frame picture of the round
  (grid, planned and driven paths, fixes, photos, obstacles, goals reached and abandoned);
* ``sim_state.json`` (simulator backends only, :func:`scenebot.robot.sim.write_sim_state`):
  the world's true robot pose at the end, so the next round's simulated world continues
  where this one stopped. It is physics state, like the room itself; no decision reads it.

Photo pattern at a goal (``adaptive.pattern``): ``fan`` takes the goal heading and
neighbours ``fan_step_deg`` apart (default 5 photos over 60 degrees: the heuristic asked for
that view, and neighbours give the new photos baselines to each other and overlap with the
map); ``circle`` takes a short circle of ``circle_photos``. The campaign's evaluation
compares the two.
"""

from __future__ import annotations

import json
import logging
import math
import re
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
from tqdm import tqdm

from scenebot.capture.predict import SCORE_SETTINGS, MatchPredictor
from scenebot.capturelog import CaptureLog, map_fingerprint, write_faults
from scenebot.config import Config
from scenebot.geometry import read_map_geometry, robot_xy_for_camera
from scenebot.robot.base import Pose2D, wrap_angle

log = logging.getLogger("scenebot.capture.adaptive")


def goal_headings(theta: float, cfg) -> list[float]:
    """Headings (rad) of the photos at a goal whose requested heading is ``theta``.

    ``fan``: theta first, then theta +- step, +- 2 step ... (``fan_photos`` in all);
    ``circle``: ``circle_photos`` evenly spaced starting at theta.
    """
    if cfg.pattern == "circle":
        n = cfg.circle_photos
        return [theta + 2 * math.pi * k / n for k in range(n)]
    step = math.radians(cfg.fan_step_deg)
    out = [theta]
    k = 1
    while len(out) < cfg.fan_photos:
        out.append(theta + k * step)
        if len(out) < cfg.fan_photos:
            out.append(theta - k * step)
        k += 1
    # sweep once from one side to the other (fewer turns, less slip)
    return sorted(out, key=lambda h: h - theta)


def map_end_pose(sfm_dir: Path, camera_offset_m: tuple[float, float]) -> Pose2D:
    """The robot pose of the map's last photo (where the previous round ended), map frame."""
    _, centres, _, headings = read_map_geometry(sfm_dir, with_headings=True)
    if len(centres) == 0:
        raise ValueError(f"{sfm_dir}: the map has no registered photos")
    th = float(headings[-1])
    fwd, left = camera_offset_m
    c, s = math.cos(th), math.sin(th)
    x = centres[-1, 0] - fwd * c + left * s
    y = centres[-1, 1] - fwd * s - left * c
    return Pose2D(float(x), float(y), th % (2 * math.pi))


def map_heading_from_compass(sfm_dir: Path) -> bool:
    """Whether a map's x axis is compass heading 0: its ``report.json`` says the heading came
    from the compass, or from the previous round's map whose heading did (followed back)."""
    sfm_dir = Path(sfm_dir)
    for _ in range(1000):
        rep = sfm_dir / "report.json"
        if not rep.is_file():
            return False
        src = (json.loads(rep.read_text(encoding="utf-8")).get("alignment") or {}).get(
            "heading_source"
        )
        if src != "previous_model":
            return src == "compass"
        m = re.fullmatch(r"round_(\d+)", sfm_dir.parent.name)
        if m is None or int(m.group(1)) == 0:
            return False
        sfm_dir = sfm_dir.parents[1] / f"round_{int(m.group(1)) - 1:03d}" / "sfm"
    return False


class SnappingPlanner:
    """A :class:`~scenebot.plan.path.GridPlanner` whose goals move off obstacle cells: a bump
    near a goal marks a disk there, and the goal then moves to the nearest free cell within
    ``snap_m`` (the planner's ``plan.goal_snap_m``) instead of being given up."""

    def __init__(self, planner, snap_m: float):
        self.planner = planner
        self.snap_m = snap_m

    def __call__(self, start_xy: np.ndarray, goal_xy: np.ndarray):
        from scenebot.plan.navgrid import snap_to_free

        snapped = snap_to_free(self.planner.grid, np.asarray(goal_xy, float), self.snap_m)
        return self.planner(start_xy, goal_xy if snapped is None else snapped)

    def mark_obstacle(self, xy: np.ndarray, radius_m: float) -> int:
        return self.planner.mark_obstacle(xy, radius_m)


def _goal_event(clog: CaptureLog, robot, event: str, index: int, goal: dict, **fields):
    from scenebot.capture.explore import log_event

    log_event(clog, robot, event, goal_index=index, goal=goal, **fields)
    log.info("goal %d: %s %s", index, event, fields.get("reason", ""))


def _go(follower, path: dict, theta: float, index: int):
    """Follow the planned path when it starts where the robot is, else plan anew."""
    wp = np.asarray(path["waypoints"], float).reshape(-1, 2)
    p = follower.pose
    if len(wp) and math.hypot(wp[0, 0] - p.x, wp[0, 1] - p.y) <= follower.cfg.node_reached_m:
        return follower.follow(wp, theta, index)
    return follower.go_to(np.asarray(path["robot_goal"], float), theta, index)


def unused_backups(goals_doc: dict, paths: list[dict]) -> list[dict]:
    """goals.json's backups the plan stage did not already put in place of a goal, by rank."""
    used = {p.get("goal", {}).get("candidate") for p in paths}
    return [b for b in goals_doc.get("backups", []) if b.get("candidate") not in used]


def visit_goals(
    paths: list[dict],
    spare: list[dict],
    go: Callable[[dict, dict | None, int], object],
    shoot: Callable[[dict, int, int], int],
    event: Callable[..., None],
    per_goal: int,
    budget: int,
) -> tuple[list[dict], int]:
    """Visit the planned goals in order and photograph each one reached.

    A goal given up on the way (``follow.max_obstacles`` bumps, no route left) is replaced by
    the next backup of ``spare`` (consumed), driven to from where the robot stands, until one
    is reached or none is left: the round still takes its photos when the map put a goal
    where the robot cannot go. Every attempt gets a ``goal_reached`` / ``goal_abandoned`` /
    ``goal_skipped`` event; a backup's carries ``backup_for`` (the goal index it replaces).

    Args:
        paths: ``paths.json``'s paths (goal, status, waypoints, robot_goal).
        spare: backup goals, best first.
        go: ``go(goal, path or None, k)`` drives there (None: plan from here) and returns a
            :class:`scenebot.capture.follow.FollowResult`.
        shoot: ``shoot(goal, k, first_photo_index)`` takes the goal's photos, returns how many.
        event: ``event(name, k, goal, **fields)`` logs a goal event.
        per_goal: photos a goal takes; ``budget``: photos of the round at most.

    Returns:
        One outcome per attempt (goal_index, status, reason, and backup_for) and the number of
        photos taken.
    """
    outcomes: list[dict] = []
    n_photos = 0
    for k, path in enumerate(paths):
        goal = path.get("goal", {})
        if n_photos + per_goal > budget:
            reason = f"photo budget of the round reached (adaptive.max_photos = {budget})"
        elif path.get("status") != "ok":
            reason = f"not planned: {path.get('message') or path.get('status')}"
        else:
            reason = None
        if reason is not None:
            event("goal_skipped", k, goal, reason=reason, robot_goal=path.get("robot_goal"))
            outcomes.append({"goal_index": k, "status": "skipped", "reason": reason})
            continue
        res = go(goal, path, k)
        extra: dict = {}
        while not res.reached:
            event("goal_abandoned", k, goal, reason=res.reason, obstacles=res.obstacles,
                  robot_goal=path.get("robot_goal") if not extra else None,
                  **extra)  # fmt: skip
            outcomes.append({"goal_index": k, "status": "abandoned", "reason": res.reason,
                             **extra})  # fmt: skip
            if not spare:
                break
            goal, extra = spare.pop(0), {"backup_for": k}
            log.info("goal %d abandoned: trying backup goal of rank %s", k, goal.get("rank"))
            res = go(goal, None, k)
        if not res.reached:
            continue
        asked = path["robot_goal"] if not extra else None
        event("goal_reached", k, goal, reason="reached", estimate=res.pose.as_dict(),
              distance_m=res.distance_m, localized_at_goal=res.localized_at_goal,
              confirmed_at_goal=res.confirmed_at_goal, robot_goal=asked,
              driven_goal=None if res.goal_xy is None else list(res.goal_xy),
              **extra)  # fmt: skip
        outcomes.append({"goal_index": k, "status": "reached", "reason": "reached", **extra})
        n_photos += shoot(goal, k, n_photos)
    return outcomes, n_photos


def _photo_at(follower, robot, camera, capture_dir: Path, name: str, localize: bool) -> dict:
    """Take a goal photo; localize it (a fix for the follower when consistent).

    Returns the fields of its ``photo`` record: sensors, ``localization`` (the map-frame
    robot pose after this photo: the photo's own fix, or the last fix carried by odometry,
    ``localization_source`` says which) and the localization's inlier count.
    """
    reading = robot.sense()
    path = camera.capture(capture_dir / name)
    rec = {"image": name, **reading.as_record()}
    source = "odometry since the last fix"
    if localize:
        est = follower.localize_photo(path, reading.odometry, reading.compass_deg)
        rec["localization_inliers"] = int(est.num_inliers)
        rec["localization_ok"] = bool(est.ok)
        if est.ok:
            source = "this photo"
    rec["localization"] = follower.pose.as_dict()
    rec["localization_source"] = source
    return rec


def run_adaptive(
    cfg: Config,
    capture_dir: Path,
    round_index: int,
    prev_round_dir: Path,
    progress: bool = True,
) -> dict:
    """Capture round ``round_index`` >= 1: visit the previous round's goals, take photos there.

    Args:
        cfg: the campaign config.
        capture_dir: ``results/{scene}/round_{r}/capture``.
        round_index: r (>= 1).
        prev_round_dir: ``results/{scene}/round_{r-1}`` (map, goals, paths, grid).
        progress: show a progress bar of photos.

    Returns:
        The round's summary (goals reached/abandoned/skipped, photos, localizations).

    Raises:
        FileNotFoundError: an input of the previous round is missing (names it).
    """
    from scenebot.capture.session import capture_lock

    if round_index < 1:
        raise ValueError("adaptive capture is for rounds >= 1 (round 0 explores)")
    if cfg.robot == "photos":
        raise ValueError("robot: photos has no robot to send to goals; set max_rounds: 1")
    with capture_lock(capture_dir):
        return _run_adaptive(cfg, Path(capture_dir), round_index, Path(prev_round_dir), progress)


def _previous_round(prev: Path, round_index: int) -> dict[str, Path]:
    """The files of round r-1 that round r drives by; a missing one is an error saying how to
    build it."""
    need = {
        "map": prev / "sfm" / "images.bin",
        "descriptors": prev / "sfm" / "point_descriptors.npz",
        "goals": prev / "goals.json",
        "paths": prev / "paths.json",
        "grid": prev / "navgrid.npz",
    }
    for what, p in need.items():
        if not p.exists():
            raise FileNotFoundError(
                f"{p}: the {what} of round {round_index - 1} is missing; build it first "
                f"(snakemake {p})"
            )
    return need


def _follow_settings(cfg: Config, sfm_dir: Path):
    """The path follower's settings: no compass check of fixes when the map's heading does
    not come from the compass."""
    fcfg = cfg.follow
    if fcfg.compass_gate_deg > 0 and not map_heading_from_compass(sfm_dir):
        log.info("the map's heading does not come from the compass: no compass check of fixes")
        fcfg = fcfg.model_copy(update={"compass_gate_deg": 0.0})
    return fcfg


def _predictor(fcfg, sfm_dir: Path, match: dict):
    """What the follower asks before a localization photo (``follow.min_matchable_points``):
    the map points a photo from a pose could match (``match``: the score settings it reads,
    by name); None when the gate is off."""
    if fcfg.min_matchable_points <= 0:
        return None
    return MatchPredictor(
        sfm_dir, **match, forward_m=fcfg.camera_forward_m, left_m=fcfg.camera_left_m
    )


class _GoalVisits:
    """What the round does at each goal, for :func:`visit_goals`: drive there (``go``), take
    the photos (``shoot``), and log what happened (``event``)."""

    def __init__(self, cfg, fcfg, robot, camera, follower, clog, capture_dir, round_index, bar):
        self.cfg, self.fcfg, self.acfg = cfg, fcfg, cfg.adaptive
        self.robot, self.camera, self.follower, self.clog = robot, camera, follower, clog
        self.capture_dir, self.round_index, self.bar = capture_dir, round_index, bar
        self.truth = getattr(robot, "truth_record", None)
        self.inliers: list[int] = []  # of the photos' localizations that succeeded

    def go(self, goal: dict, path: dict | None, k: int):
        if path is not None:
            return _go(self.follower, path, float(goal["theta"]), k)
        xy = np.array([goal["x"], goal["y"]], float)
        return self.follower.go_to_view(xy, float(goal["theta"]), k)

    def shoot(self, goal: dict, k: int, first: int) -> int:
        follower, robot = self.follower, self.robot
        for j, h in enumerate(goal_headings(float(goal["theta"]), self.acfg)):
            turn = wrap_angle(h - follower.pose.theta)
            if abs(math.degrees(turn)) > self.fcfg.min_turn_deg:
                robot.turn(turn)
            name = f"images/r{self.round_index:03d}_{first + j:04d}.jpg"
            rec = _photo_at(follower, robot, self.camera, self.capture_dir, name,
                            self.acfg.localize_photos)  # fmt: skip
            record = {"type": "photo", "index": first + j, **rec, "goal_index": k,
                      "requested_heading": h % (2 * math.pi)}  # fmt: skip
            if self.truth is not None:
                record["truth"] = self.truth()
            self.clog.write(record)
            if rec.get("localization_ok"):
                self.inliers.append(rec["localization_inliers"])
            self.bar.update(1)
        return j + 1

    def event(self, name: str, k: int, goal: dict, **fields):
        if fields.get("robot_goal") is None and "theta" in goal:  # a backup goal
            xy = np.array([goal["x"], goal["y"]], float)
            mount = self.cfg.camera_mount()
            fields["robot_goal"] = robot_xy_for_camera(xy, goal["theta"], mount).tolist()
        _goal_event(self.clog, self.robot, name, k, goal, **fields)


def _round_summary(round_index: int, n_photos: int, paths: list, outcomes: list[dict],
                   capture_dir: Path, inliers: list[int], world) -> dict:  # fmt: skip
    """The capture log's ``end`` record (and the command's output)."""
    summary = {
        "round": round_index,
        "photos": n_photos,
        "goals": len(paths),
        "backups_tried": sum("backup_for" in o for o in outcomes),
        "reached": sum(o["status"] == "reached" for o in outcomes),
        "abandoned": sum(o["status"] == "abandoned" for o in outcomes),
        "skipped": sum(o["status"] == "skipped" for o in outcomes),
        "outcomes": outcomes,
        "nav_photos": len(list((capture_dir / "nav").glob("*.jpg"))),
        "photos_localized": len(inliers),
        "localization_inliers_median": float(np.median(inliers)) if inliers else None,
    }
    if world is not None:
        summary["max_penetration_m"] = world.max_penetration_m
    return summary


def _run_adaptive(
    cfg: Config, capture_dir: Path, round_index: int, prev: Path, progress: bool
) -> dict:
    """:func:`run_adaptive` holding the capture lock."""
    from scenebot.capture.follow import PathFollower
    from scenebot.capture.session import (
        SESSION_LOG,
        finish_capture,
        session_record,
        start_capture,
        stopping_safely,
    )
    from scenebot.localize import make_localizer
    from scenebot.plan.navgrid import NavGrid
    from scenebot.plan.path import GridPlanner
    from scenebot.robot.factory import make_backend

    need = _previous_round(prev, round_index)
    goals_doc = json.loads(need["goals"].read_text(encoding="utf-8"))
    paths_doc = json.loads(need["paths"].read_text(encoding="utf-8"))
    fcfg, acfg = _follow_settings(cfg, prev / "sfm"), cfg.adaptive
    per_goal = acfg.circle_photos if acfg.pattern == "circle" else acfg.fan_photos
    paths = paths_doc.get("paths", [])
    budget = min(acfg.max_photos, per_goal * len(paths))

    start_capture(capture_dir, ("images", "nav"))
    robot, camera, world = make_backend(cfg, capture_dir, previous_capture=prev / "capture")
    planner = SnappingPlanner(
        GridPlanner(NavGrid.load(need["grid"]), cfg.plan.simplify_factor), cfg.plan.goal_snap_m
    )
    initial = map_end_pose(prev / "sfm", cfg.camera_mount())
    outcomes: list[dict] = []
    n_photos = 0
    with (
        tempfile.TemporaryDirectory(prefix="scenebot-index-") as tmp,
        CaptureLog(capture_dir / SESSION_LOG) as clog,
        robot,
    ):
        localizer = make_localizer(prev / "sfm", cfg.localize, cache_file=Path(tmp) / "i.flann")
        match = {k: getattr(cfg.score, k) for k in SCORE_SETTINGS}  # the gate's settings
        clog.write(
            session_record(
                cfg, robot, world, round_index, {"world", "sim", "follow", "adaptive", "localize"},
                map=str(prev / "sfm"), map_sha1=map_fingerprint(prev / "sfm"),
                match_settings=match,
                previous_round_complete=goals_doc.get("complete"),
                initial_estimate=initial.as_dict(),
            )
        )  # fmt: skip
        bar = tqdm(total=budget, desc=f"round {round_index} photos", unit="photo",
                   disable=not progress)  # fmt: skip
        follower = PathFollower(
            robot, camera, localizer, planner, fcfg, capture_dir / "nav", clog,
            truth=getattr(robot, "truth_record", None), initial_pose=initial,
            trust_initial=False, predictor=_predictor(fcfg, prev / "sfm", match),
        )  # fmt: skip
        visits = _GoalVisits(cfg, fcfg, robot, camera, follower, clog, capture_dir,
                             round_index, bar)  # fmt: skip
        with stopping_safely(clog, robot, capture_dir, world, bar):
            follower.localize_now()  # where the robot really is, before the first path
            spare = unused_backups(goals_doc, paths) if acfg.replace_abandoned else []
            outcomes, n_photos = visit_goals(
                paths, spare, visits.go, visits.shoot, visits.event, per_goal, budget
            )
        summary = _round_summary(round_index, n_photos, paths, outcomes, capture_dir,
                                 visits.inliers, world)  # fmt: skip
        write_faults(clog, robot)  # the faults recovered after the last photo or event
        clog.write({"type": "end", "t": robot.now, "reason": "goals visited", **summary})
    finish_capture(
        capture_dir,
        lambda out, png: plot_round(out, png, need["grid"], paths_doc),
        ("images", "nav"),
    )
    return summary


def plot_round(log_path: Path, png: Path, grid_npz: Path, paths_doc: dict) -> Path:
    """Map-frame picture of an adaptive round: the grid it planned on, the planned paths, the
    estimated track (fixes and odometry), the photos, obstacles, and each goal's outcome."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from scenebot.capturelog import read_log
    from scenebot.plan.navgrid import NavGrid

    grid = NavGrid.load(grid_npz)
    g = grid.geometry
    ny, nx = g.shape
    ext = (g.origin_xy[0], g.origin_xy[0] + nx * g.cell_m,
           g.origin_xy[1], g.origin_xy[1] + ny * g.cell_m)  # fmt: skip
    records = list(read_log(log_path))
    fig, ax = plt.subplots(figsize=(8, 8 * ny / max(nx, 1) + 0.6), dpi=110)
    ax.imshow(np.log1p(grid.score), origin="lower", extent=ext, cmap="Greys",
              interpolation="nearest")  # fmt: skip
    red = np.zeros((ny, nx, 4))
    red[grid.lethal] = (0.8, 0.1, 0.1, 0.2)
    ax.imshow(red, origin="lower", extent=ext, interpolation="nearest")
    for p in paths_doc.get("paths", []):
        if p.get("status") == "ok":
            wp = np.asarray(p["waypoints"], float)
            ax.plot(wp[:, 0], wp[:, 1], ":", color="tab:blue", lw=1)
    track = np.array(
        [[r["estimate"]["x"], r["estimate"]["y"]] for r in records if "estimate" in r] + [[0, 0]]
    )[:-1]
    if len(track):
        ax.plot(
            track[:, 0], track[:, 1], "-", color="tab:orange", lw=1.2, label="driven (estimate)"
        )
    fixes = np.array([r["localization"]["center"][:2] for r in records
                      if r.get("event") == "localize"]).reshape(-1, 2)  # fmt: skip
    if len(fixes):
        ax.plot(fixes[:, 0], fixes[:, 1], ".", ms=5, color="tab:purple",
                label=f"visual fixes ({len(fixes)})")  # fmt: skip
    photos = [r for r in records if r.get("type") == "photo" and r.get("localization")]
    for r in photos:
        q = r["localization"]
        ax.arrow(q["x"], q["y"], 0.2 * math.cos(q["theta"]), 0.2 * math.sin(q["theta"]),
                 width=0.006, color="tab:green", head_width=0.04, alpha=0.8,
                 length_includes_head=True)  # fmt: skip
    ax.plot([], [], color="tab:green", lw=3, label=f"photos ({len(photos)})")
    obstacles = np.array([[r["estimate"]["x"], r["estimate"]["y"]] for r in records
                          if r.get("event") == "obstacle"]).reshape(-1, 2)  # fmt: skip
    if len(obstacles):
        ax.scatter(obstacles[:, 0], obstacles[:, 1], marker="x", color="red", s=60, zorder=5,
                   label=f"bumps/stalls ({len(obstacles)})")  # fmt: skip
    style = {"goal_reached": ("*", "gold"), "goal_abandoned": ("X", "red"),
             "goal_skipped": ("X", "grey")}  # fmt: skip
    for ev, (marker, color) in style.items():
        sel = [r["goal"] for r in records if r.get("event") == ev and "x" in r.get("goal", {})]
        pts = np.array([[q["x"], q["y"]] for q in sel]).reshape(-1, 2)
        if len(pts):
            ax.scatter(pts[:, 0], pts[:, 1], marker=marker, s=160, color=color, ec="k",
                       zorder=6, label=f"{ev.replace('_', ' ')} ({len(pts)})")  # fmt: skip
    ax.set_aspect("equal")
    ax.set_xlabel("x (m, map frame)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"{Path(log_path).parent.parent.name}: adaptive capture, map frame")
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(png)
    plt.close(fig)
    return Path(png)
