"""The ``plan`` stage: navigation grid of round r's map and a path to every goal.

Inputs: ``round_{r}/sfm/`` (COLMAP binary model, map frame: cameras in z = 0, z up, metres)
and ``round_{r}/goals.json``. Outputs: ``round_{r}/navgrid.npz`` (see
:meth:`scenebot.plan.navgrid.NavGrid.save`), ``round_{r}/paths.json`` and, with
``cfg.plot``, ``round_{r}/navgrid.png``.

``goals.json`` is read leniently: either a list of goals or an object with a ``goals`` list;
a goal is ``{"x": .., "y": .., "theta": ..}`` (camera centre in m, heading in rad, as the
goals stage writes them; extra keys are kept) or ``[x, y, theta]``. Paths lead the robot's
rotation axis to ``robot_goal``, the spot from which the camera centre lands on the goal.

Paths are chained: start -> goal 0 -> goal 1 -> ...; a skipped goal (outside the grid, in an
obstacle, no route) is recorded with its reason and the chain continues from the last goal
that was reached. The start is ``start_xy`` when given, else the centre of the map's last
image in name order (where the robot stopped in the latest round).

``paths.json``::

    {"grid": {"origin_xy", "cell_m", "shape"}, "start": [x, y], "config": {...},
     "paths": [{"goal_index", "goal": {...}, "from": [x, y], "status": "ok", "waypoints":
                [[x, y], ...], "length_m", "cost", "astar_cost", ...}
               | {"goal_index", "goal", "from", "status": "skipped", "reason", "message"}]}
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scenebot.geometry import read_map_geometry, robot_xy_for_camera
from scenebot.plan.config import PlanConfig
from scenebot.plan.navgrid import NavGrid, build_navgrid, snap_to_free
from scenebot.plan.path import PlanFailure, plan_path


@dataclass(frozen=True)
class PlanInputs:
    """Files the stage reads."""

    sfm_dir: Path
    goals_json: Path


@dataclass(frozen=True)
class PlanOutputs:
    """Files the stage writes."""

    navgrid_npz: Path
    paths_json: Path
    plot_png: Path | None = None


def read_goals(goals_json: Path, key: str = "goals") -> list[dict]:
    """Goals (or with ``key="backups"`` the backups) as dicts with at least ``x`` and ``y``
    (m), see the module docstring."""
    goals_json = Path(goals_json)
    data = json.loads(goals_json.read_text(encoding="utf-8"))
    if not isinstance(data, dict) and key != "goals":
        return []
    items = data.get(key, []) if isinstance(data, dict) else data
    goals = []
    for i, g in enumerate(items):
        if isinstance(g, dict) and "x" in g and "y" in g:
            goals.append(dict(g))
        elif isinstance(g, list | tuple) and len(g) >= 2:
            goals.append({"x": g[0], "y": g[1], **({"theta": g[2]} if len(g) > 2 else {})})
        else:
            raise ValueError(f"{goals_json}: goal {i} is neither {{x, y, ...}} nor [x, y, theta]")
    return goals


def plan_all(
    grid: NavGrid,
    start_xy: np.ndarray,
    goals: list[dict],
    cfg: PlanConfig,
    camera_offset_m: tuple[float, float] = (0.0, 0.0),
    backups: list[dict] | None = None,
) -> list[dict]:
    """Chained paths start -> goal 0 -> goal 1 ...; skipped goals carry their reason.

    A goal that cannot be planned to is replaced by the next unused backup (goals.json's
    ``backups``, next in rank) that can; the record then lists the goals it replaced
    (``replaced``, with their reasons). Without a working backup the goal stays, skipped.

    Goals are camera poses (goals.json's convention: camera centre x, y and heading theta);
    the path leads the robot's rotation axis to where the camera centre lands on the goal
    (``robot_goal`` in the records). A goal without ``theta`` is taken as a robot position.
    """
    here = np.asarray(start_xy, float)
    spare = list(backups or [])
    out = []
    for i, goal in enumerate(goals):
        gxy, res, extra = _plan_one(grid, here, goal, cfg, camera_offset_m)
        replaced = []
        while isinstance(res, PlanFailure) and spare:
            replaced.append({"goal": goal, "reason": str(res.reason), "message": res.message})
            goal = spare.pop(0)
            gxy, res, extra = _plan_one(grid, here, goal, cfg, camera_offset_m)
        rec = {
            "goal_index": i,
            "goal": goal,
            "robot_goal": gxy.tolist(),
            "from": here.tolist(),
            **extra,
            **({"replaced": replaced} if replaced else {}),
            **res.as_dict(),
        }
        out.append(rec)
        if not isinstance(res, PlanFailure):
            here = gxy
    return out


def _plan_one(grid: NavGrid, here: np.ndarray, goal: dict, cfg: PlanConfig, camera_offset_m):
    """(robot goal position, plan or failure, snapping record) of one goal."""
    gxy = np.array([float(goal["x"]), float(goal["y"])])
    if goal.get("theta") is not None:
        gxy = robot_xy_for_camera(gxy, float(goal["theta"]), camera_offset_m)
    snapped = snap_to_free(grid, gxy, cfg.goal_snap_m)
    extra = {}
    if snapped is not None and not np.allclose(snapped, gxy):
        extra = {"snapped_from": gxy.tolist(), "snap_m": float(np.hypot(*(snapped - gxy)))}
        gxy = snapped
    return gxy, plan_path(grid, here, gxy, cfg.simplify_factor), extra


def run(
    cfg: PlanConfig,
    inputs: PlanInputs,
    outputs: PlanOutputs,
    start_xy: tuple[float, float] | None = None,
    camera_offset_m: tuple[float, float] = (0.0, 0.0),
) -> dict:
    """Build the navigation grid and plan the paths to every goal.

    Args:
        cfg: plan settings.
        inputs: the map folder and goals file.
        outputs: where to write the grid, the paths and the picture.
        start_xy: robot position (m, map frame); default: the robot position of the map's
            last image (its camera centre minus the camera offset).
        camera_offset_m: camera centre (forward, left) of the robot's rotation axis (m);
            the simulator's camera.forward_offset_m / lateral_offset_m.

    Returns:
        The ``paths.json`` content.
    """
    points, centres, _, headings = read_map_geometry(inputs.sfm_dir, with_headings=True)
    if len(centres) == 0:
        raise ValueError(f"{inputs.sfm_dir}: the model has no registered images")
    goals = read_goals(inputs.goals_json)
    backups = read_goals(inputs.goals_json, "backups")
    # the explored area: where the robot has been and where it is asked to go (goals lie in
    # the map's free space, which reaches beyond the camera positions); a goal outside the
    # map's points is no part of it and is skipped as outside the grid
    extent = centres[:, :2]
    if goals and len(points):
        gxy = np.array([[g["x"], g["y"]] for g in goals + backups], float)
        lo, hi = points[:, :2].min(axis=0), points[:, :2].max(axis=0)
        inside = np.all((gxy >= lo) & (gxy <= hi), axis=1)
        extent = np.vstack([extent, gxy[inside]])
    grid = build_navgrid(points, extent, cfg)
    grid.save(outputs.navgrid_npz)
    if start_xy is not None:
        start = np.asarray(start_xy, float)
    else:
        start = robot_xy_for_camera(centres[-1, :2], headings[-1], camera_offset_m)
    paths = plan_all(grid, start, goals, cfg, camera_offset_m, backups)
    g = grid.geometry
    doc = {
        "grid": {"origin_xy": list(g.origin_xy), "cell_m": g.cell_m, "shape": list(g.shape)},
        "start": start.tolist(),
        "config": cfg.model_dump(),
        "paths": paths,
    }
    outputs.paths_json.parent.mkdir(parents=True, exist_ok=True)
    outputs.paths_json.write_text(json.dumps(doc, indent=1), encoding="utf-8")
    if cfg.plot and outputs.plot_png is not None:
        from scenebot.plan.plots import plot_navgrid

        ok = [np.array(p["waypoints"]) for p in paths if p["status"] == "ok"]
        gxy = np.array([p["robot_goal"] for p in paths if p["status"] == "ok"])
        sxy = np.array([p["robot_goal"] for p in paths if p["status"] != "ok"])
        plot_navgrid(
            grid,
            ok,
            outputs.plot_png,
            goals_xy=gxy.reshape(-1, 2),
            skipped_xy=sxy.reshape(-1, 2),
            camera_xy=centres[:, :2],
            title=f"navigation grid ({g.shape[1]}x{g.shape[0]} cells of {g.cell_m:.3f} m)",
        )
    return doc
