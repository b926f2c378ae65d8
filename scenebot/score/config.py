"""Settings of the mesh, score and goals stages (issue 4).

Three small pydantic models, one per stage, so that the lead can nest them in the single
project config (e.g. ``mesh:``, ``score:``, ``goals:`` sections of ``config.yaml``).
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class MeshConfig(BaseModel):
    """Poisson mesh of the sparse map and the free space cut from it (``mesh`` stage)."""

    model_config = ConfigDict(extra="forbid")

    min_track_length: int = Field(
        2, ge=2, description="Only 3D points seen in at least this many images are meshed."
    )
    normal_knn: int = Field(
        20, ge=3, description="Neighbours (count) used to estimate each point's normal."
    )
    poisson_depth: int = Field(
        8, ge=4, le=12, description="Octree depth of Poisson reconstruction (2^depth cells/side)."
    )
    density_quantile: float = Field(
        0.05,
        ge=0.0,
        lt=1.0,
        description="Vertices whose Poisson density is below this quantile are trimmed (0..1).",
    )
    bbox_margin_m: float = Field(
        0.25, ge=0.0, description="Mesh is cropped to the points' bounding box grown by this (m)."
    )
    min_points: int = Field(
        50, ge=4, description="Fewer usable 3D points than this is an error (count)."
    )
    max_point_range_m: float = Field(
        12.0,
        gt=0.0,
        description="3D points farther than this (m) from every camera are not meshed: "
        "triangulations of nearly parallel rays, hundreds of metres out, that would stretch "
        "the mesh and the free-space raster over nothing (a room is a few metres).",
    )
    robot_radius_m: float = Field(
        0.15, gt=0.0, description="Robot footprint radius (m): free space keeps this from walls."
    )
    seen_free_space: bool = Field(
        True,
        description="Free space only where the cameras saw across it: the lines of sight from "
        "each camera to the points it observed, seen from above, cover it, and the robot keeps "
        "its radius from space they do not (where a plain wall left a hole in the map, its "
        "Poisson surface bulges out of the room and the cut alone leaks through; "
        "score.freespace.ray_coverage).",
    )
    cut_heights_m: list[float] = Field(
        default_factory=lambda: [0.0],
        min_length=1,
        description=(
            "Heights (m, robot frame, 0 = camera plane) at which the mesh is cut to find "
            "obstacles; the paper uses the camera plane only."
        ),
    )
    grid_resolution_m: float = Field(
        0.02, gt=0.0, description="Cell size of the free-space raster (m)."
    )


class ScoreConfig(BaseModel):
    """Candidate viewpoints and the rendering-quality score (``score`` stage)."""

    model_config = ConfigDict(extra="forbid")

    n_candidates: int = Field(2000, ge=1, description="Random candidate poses to score (count).")
    seed: int = Field(0, description="Seed of the candidate sampler.")
    width: int = Field(80, ge=4, description="Width of the virtual candidate render (pixels).")
    height: int = Field(60, ge=3, description="Height of the virtual candidate render (pixels).")
    source_depth_width: int = Field(
        160, ge=8, description="Width of each source camera's depth map (pixels)."
    )
    depth_tolerance: float = Field(
        0.03,
        ge=0.0,
        description=(
            "Relative depth tolerance of the source visibility test: P is seen by C_i when its "
            "depth is <= (1 + tolerance) x the largest depth of the 2x2 depth-map pixels around "
            "its projection (fraction)."
        ),
    )
    near_m: float = Field(0.02, gt=0.0, description="Near clipping distance of all renders (m).")
    max_triangles: int = Field(
        10000,
        ge=0,
        description="Mesh is decimated to at most this many triangles for scoring (0 = keep all).",
    )
    batch_size: int = Field(256, ge=1, description="Candidates rendered per taichi launch.")
    backend: Literal["auto", "cpu", "gpu"] = Field(
        "auto",
        description="Taichi backend: auto = CUDA/Vulkan if present else CPU; gpu = fail if none.",
    )
    match_angle_deg: float = Field(
        45.0,
        gt=0.0,
        le=180.0,
        description="A candidate can match a map point it sees within this angle of the mean "
        "direction the map's cameras saw it from (degrees; SIFT's viewpoint range). Counted "
        "per candidate as `matchable_points` (score.matchable).",
    )
    match_scale_ratio: float = Field(
        2.0,
        ge=1.0,
        description="...and from a distance within this factor, either way, of the map "
        "cameras' mean distance to it (SIFT's scale range).",
    )
    plot_top: int = Field(4, ge=0, description="Top candidates drawn as per-pixel score images.")


class GoalsConfig(BaseModel):
    """Choice of goals among the scored candidates (``goals`` stage)."""

    model_config = ConfigDict(extra="forbid")

    method: Literal["score", "frontier"] = Field(
        "score",
        description="score: the paper's heuristic (poorest predicted rendering first); "
        "frontier: the baseline, nearest boundary between seen and unseen free space first.",
    )
    k: int = Field(5, ge=1, description="Most goals chosen per round (count).")
    backups: int = Field(
        5,
        ge=0,
        description="Next-ranked candidates listed as backups: the plan stage takes one in "
        "place of a goal it cannot route to (inside an obstacle of its grid, outside it, or "
        "walled off).",
    )
    frontier_range_m: float = Field(
        3.0, gt=0, description="frontier: a photo sees free space up to this distance (m)."
    )
    frontier_min_area_m2: float = Field(
        0.25, ge=0, description="frontier: unseen free space in smaller pieces is ignored (m^2)."
    )
    frontier_look_m: float = Field(
        1.0, gt=0, description="frontier: a goal looks at the unseen free space this near (m)."
    )
    nms_radius_m: float = Field(
        0.5, ge=0.0, description="Two goals closer than this (m) must differ in heading."
    )
    nms_angle_deg: float = Field(
        45.0, ge=0.0, le=180.0, description="...by more than this heading difference (degrees)."
    )
    complete_threshold_deg: float = Field(
        10.0,
        ge=0.0,
        description="Exploration is complete when the best (highest) view score is below this.",
    )
    min_score_gain: float = Field(
        0.15,
        ge=0.0,
        lt=1.0,
        description="Diminishing returns: exploration is also complete when, since the "
        "previous round, the mean view score over the candidates (the predicted rendering "
        "error over the free space) moved by less than this fraction either way and the free "
        "space grew by less than min_area_gain. The best score alone rarely falls below "
        "complete_threshold_deg: a view of never-photographed surface (ceiling, behind "
        "furniture) keeps it high. 0: off.",
    )
    min_area_gain: float = Field(
        0.1,
        ge=0.0,
        description="See min_score_gain: a round whose photos added free space the map did "
        "not know (farther than new_area_margin_m from the previous round's free space) of "
        "this fraction of the previous free area or more opened space (another room, a "
        "corridor), and exploration goes on. Without the previous round's free space: the "
        "net growth of the free area.",
    )
    patience: int = Field(
        2,
        ge=1,
        description="Diminishing returns must hold in this many consecutive rounds: one "
        "round's gain varies from campaign to campaign (the same office: 12% in one, 22% in "
        "another), so a single low round does not end the campaign.",
    )
    new_area_margin_m: float = Field(
        0.3,
        ge=0.0,
        description="Free space within this distance (m) of the previous round's does not "
        "count as new (its outline moves a little as the map improves).",
    )
    min_seen_fraction: float = Field(
        0.4,
        ge=0.0,
        le=1.0,
        description="Candidates whose view shows less of the map's already photographed "
        "surface than this share of its pixels are not goals: a photo there could not be "
        "registered to the map (too little overlap). 0: the paper's choice, overlap ignored.",
    )
    min_matchable_points: int = Field(
        100,
        ge=0,
        description="Candidates predicted to match fewer of the map's 3D points than this "
        "(candidates.csv `matchable_points`: in view, seen within score.match_angle_deg and "
        "score.match_scale_ratio of how the map saw them) are not goals: their photos would "
        "not register. An area of photographed surface is not enough: a plain wall at a "
        "grazing angle has no features. 0: off.",
    )
    min_hit_fraction: float = Field(
        0.2,
        ge=0.0,
        le=1.0,
        description="Candidates whose render hits the mesh on fewer pixels than this are skipped.",
    )
