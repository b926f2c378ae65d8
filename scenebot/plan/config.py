"""Configuration of the ``plan`` stage (navigation grid, A*, path simplification)."""

from __future__ import annotations

from pydantic import Field

from scenebot.settings import Settings


class PlanConfig(Settings):
    """Settings of the navigation grid and the path planner (paper section IV.B)."""

    n_cells: int = Field(
        100, ge=4, le=4000, description="Grid cells along the larger dimension of the grid."
    )
    margin_m: float = Field(
        1.0,
        ge=0.0,
        description="Margin (m) added on every side of the bounding box of the camera centres "
        "(the explored area) before the grid is laid over it.",
    )
    obstacle_z_min_m: float = Field(
        0.0,
        description="3D points with z above this (m, map frame, camera plane at z = 0) count as "
        "obstacles; the paper's conservative threshold is 0.",
    )
    obstacle_z_max_m: float | None = Field(
        None,
        description="Optional upper bound (m) on obstacle z, e.g. to ignore the ceiling; "
        "None counts every point above obstacle_z_min_m (the paper).",
    )
    kde_sigma_m: float = Field(
        0.1, gt=0.0, description="Standard deviation (m) of the Gaussian KDE weights (eq. 1)."
    )
    kde_truncate: float = Field(
        3.0, gt=0.0, description="Neighbourhood N of eq. 1 extends this many sigmas each way."
    )
    lethal_points: float = Field(
        3.0,
        gt=0.0,
        description="A cell is lethal (an obstacle) when the Gaussian-weighted count of obstacle "
        "points around it, |N| * K(c), reaches this value (points).",
    )
    inflate_m: float = Field(
        0.15,
        ge=0.0,
        description="Lethal cells are grown by this radius (m): the robot's footprint radius "
        "(the simulated robot's sim.body.radius_m is 0.15).",
    )
    cost_weight: float = Field(
        1.0,
        ge=0.0,
        description="Travel cost per metre of a non-lethal cell is 1 + cost_weight * |N| * K(c).",
    )
    simplify_factor: float = Field(
        1.1,
        ge=1.0,
        description="Path simplification may replace a run of moves by one straight move when "
        "its cost is at most this multiple of the original moves' cost.",
    )
    goal_snap_m: float = Field(
        0.3,
        ge=0,
        description="A goal whose robot position falls in an obstacle cell moves to the "
        "nearest free cell within this distance (m), keeping its heading; farther: skipped.",
    )
    plot: bool = Field(True, description="Write the Fig. 4-like picture round_{r}/navgrid.png.")
