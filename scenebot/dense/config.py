"""Configuration of the dense multi-view stereo stage (issue 7).

The lead merges :class:`DenseConfig` into the single project config; every field carries its
unit in the description so the generated JSON schema documents itself.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from scenebot.settings import Settings


class PatchMatchConfig(Settings):
    """Settings of the taichi PatchMatch stereo (and of pycolmap's CUDA one where used)."""

    iterations: list[int] = Field(
        [1, 1, 3, 3],
        min_length=1,
        max_length=6,
        description="Red-black PatchMatch iterations per pyramid level, index 0 = full "
        "resolution, each next level half the size; the coarsest starts from random planes.",
    )
    neighbors: list[Literal[4, 8]] = Field(
        [4, 4, 8],
        min_length=1,
        description="Propagation candidates per pixel per level (4 at distance 1, plus 4 at "
        "distance 3); levels beyond the list use its last entry.",
    )
    fine_view_selection: bool = Field(
        True,
        description="At full resolution evaluate only each pixel's top_k sources chosen for the "
        "upsampled hypothesis (halves the work with top_k=2 of 4 sources).",
    )
    view_selection_levels: int = Field(
        1,
        ge=1,
        le=6,
        description="With fine_view_selection: the finest this many pyramid levels evaluate "
        "each pixel's selected sources only (1: full resolution alone).",
    )
    geom_iterations: int = Field(
        1, ge=0, le=10, description="Geometric-consistency iterations at full resolution."
    )
    window_radius: int = Field(
        3, ge=1, le=10, description="NCC window half size, pixels (window is 2r+1 wide)."
    )
    window_step: int = Field(2, ge=1, le=4, description="Sampling step inside the window, pixels.")
    sigma_color: float = Field(
        0.2, gt=0, description="Bilateral NCC colour sigma, grey levels in [0, 1]."
    )
    sigma_spatial: float = Field(
        -1.0, description="Bilateral NCC spatial sigma, pixels; <= 0 means window_radius."
    )
    top_k: int = Field(
        2, ge=1, le=8, description="View selection: the cost is the mean of the k best sources."
    )
    geom_weight: float = Field(
        0.3, ge=0, description="Weight of the forward-backward reprojection error, per pixel."
    )
    geom_max_error: float = Field(
        3.0, gt=0, description="Truncation of the forward-backward reprojection error, pixels."
    )
    filter_max_cost: float = Field(
        0.5, gt=0, le=2, description="Keep a pixel if its photometric cost (1 - NCC) is below."
    )
    filter_min_consistent: int = Field(
        1, ge=0, le=8, description="Keep a pixel if at least this many sources agree geometrically."
    )
    filter_max_reproj_error: float = Field(
        1.0, gt=0, description="Forward-backward error for a source to agree, pixels."
    )
    filter_max_rel_depth_error: float = Field(
        0.01, gt=0, description="Relative depth difference for a source to agree (fraction)."
    )
    seed: int = Field(0, description="Random seed of the hypothesis initialisation.")


class PlaneFillConfig(Settings):
    """Plane completion of the depth maps before fusion (:mod:`scenebot.dense.planefill`)."""

    enabled: bool = Field(
        True,
        description=(
            "Fill holes of the depth maps (plain walls, floor, ceiling) from planes found in "
            "the measured depth, where the hole's nearest measured neighbours lie on the plane."
        ),
    )
    voxel_m: float = Field(0.02, gt=0, description="Voxel size (m) thinning the plane search.")
    points_per_view: int = Field(
        20000, ge=100, description="Measured points drawn per view for the plane search."
    )
    ransac_distance_m: float = Field(0.015, gt=0, description="RANSAC inlier distance (m).")
    normal_deg: float | None = Field(
        30.0,
        gt=0,
        le=90,
        description=(
            "A point supports a plane only where its stereo normal lies within this angle "
            "(degrees) of the plane's (oriented RANSAC); null: positions only (open3d "
            "segment_plane), which lets planes cut across several surfaces."
        ),
    )
    snap_deg: float = Field(
        10.0,
        ge=0,
        lt=45,
        description="Planes within this angle (degrees) of horizontal or vertical are made "
        "exactly so, relative to the largest plane near the map's horizontal (the floor), "
        "and their offset set to their inliers' median: walls stand upright; 0: as fitted. "
        "RANSAC over the points of two parallel walls a few cm apart fits a plane several "
        "degrees off (5 degrees in one office campaign), whose fill then cuts across both.",
    )
    merge_angle_deg: float = Field(
        5.0, gt=0, description="Planes closer than this (and 2 RANSAC distances) are one."
    )
    min_plane_share: float = Field(
        0.005,
        gt=0,
        lt=1,
        description="Smallest plane, as a share of the voxel points, that is used.",
    )
    max_planes: int = Field(24, ge=1, description="At most this many planes.")
    ceiling_min_points: int = Field(
        25,
        ge=0,
        description="The ceiling, seen by a level camera in its photos' top rows only, is "
        "too small a share for RANSAC: it is found as the highest height above every camera "
        "where this many voxel points with vertical normals lie, three times as many as the "
        "same width holds on average within 15 cm around it, nothing measured above it, and "
        "it spans the floor's extent; 0: no ceiling search. Office campaigns of 200 photos "
        "measured 429, about 100 and about 55 such points within 1.5 cm of their ceiling (the "
        "last missed at 60); the test that nothing lies above it keeps desk and cabinet tops "
        "out.",
    )
    extent_cell_m: float = Field(
        0.1, gt=0, description="Cell (m) of the raster that holds a plane's extent."
    )
    extent_min_points: int = Field(
        3, ge=1, description="Inliers a raster cell needs to belong to the plane's extent."
    )
    extent_close_cells: int = Field(
        6,
        ge=0,
        description=(
            "Morphological closing (cells) of the extent: bridges gaps up to about twice "
            "this many cells (plain paint between textured patches). Wide extents need "
            "dense.plane_fill.drop_phantoms, or phantom planes remove real depth."
        ),
    )
    extent: Literal["cells", "carved_hull"] = Field(
        "carved_hull",
        description="A plane's extent: cells, the raster cells holding its points (closed "
        "over extent_close_cells); carved_hull, their convex hull less the cells that "
        "measured depth beyond the plane is seen through (doorways, the room beyond a plane "
        "that ends), so a plain wall spans the space between its posters, corners and edges.",
    )
    carve_min_rays: int = Field(
        2, ge=1, description="carved_hull: rays seen through a cell that carve it out."
    )
    label_distance_m: float = Field(
        0.02, gt=0, description="A measured pixel lies on a plane within this distance (m) ..."
    )
    label_rel_distance: float = Field(
        0.01, ge=0, description="... or this share of its depth, whichever is larger."
    )
    cell_px: int = Field(4, ge=1, description="Cell size (px) of the neighbour vote.")
    max_gap_frac: float = Field(
        0.5,
        gt=0,
        le=1,
        description="A hole looks this far (share of the image width) for measured depth.",
    )
    fill_rule: Literal["same_plane", "bounding_planes"] = Field(
        "bounding_planes",
        description="same_plane: a hole is filled with the plane most of its 8 nearest "
        "measured neighbours lie on; bounding_planes: a hole whose neighbours lie on planes "
        "(any planes: wall, floor, another wall) is filled, each pixel with the boundary plane "
        "its ray meets first (boundaries are found by extent: carved_hull; with extent: "
        "cells only an object face's same_plane fill remains).",
    )
    fill_planes: Literal["neighbours", "any_boundary"] = Field(
        "any_boundary",
        description="bounding_planes: the planes a hole's pixel may take, front-most first: "
        "neighbours, the boundary planes its measured neighbours lie on; any_boundary, any "
        "boundary of the room its ray meets (a plain ceiling above plain walls, where no "
        "neighbour lies on the ceiling).",
    )
    passes: int = Field(
        3,
        ge=1,
        le=5,
        description="Fill passes: each later pass counts the earlier fill as measured, so a "
        "plain wall's fill spreads across the cells whose neighbours the first pass lacked.",
    )
    occlusion_min_points: int = Field(
        4,
        ge=0,
        description="Empty again the filled pixels behind at least this many points of the "
        "measured depth of all views projected into the view's cell (cell_px; a plain object "
        "that the fill spread across, whose texture other views measured); 0: no check.",
    )
    sparse_veto: bool = Field(
        True,
        description="Empty again the filled pixels that the view's own SfM points contradict "
        "(a close object stereo missed, its features in front of the filled wall): the "
        "Delaunay triangles of the view's observations whose three corners lie off the fill "
        "by > 5% (planes.vetoes.sparse_contradicted_fill).",
    )
    floor_to_walls: bool = Field(
        True,
        description="The floor's extent reaches the bottom edges of the room's walls (boundary "
        "planes), gaps up to 0.6 m closed: a corner of the floor is seen only at grazing "
        "angles from across the room, and the floor's carved hull cut it off "
        "(planes.extents.span_walls).",
    )
    walls_to_ceiling_m: float = Field(
        1.2,
        ge=0,
        description="With a ceiling found: the room's walls (boundary planes) rise to it from "
        "their highest measured cells when it is less than this (m) above them (a level "
        "camera measures the top of a wall only from across the room; "
        "planes.extents.span_to_ceiling); 0: off.",
    )
    sparse_veto_max_edge_px: float = Field(
        120.0,
        gt=0,
        description="Longest triangle edge (px, at the dense image size) of sparse_veto.",
    )
    min_votes: int = Field(
        2, ge=1, le=8, description="Of the 8 directions, this many must find the same plane ..."
    )
    min_agreement: float = Field(
        0.6, gt=0, le=1, description="... and this share of the directions that found depth."
    )
    extent_margin_m: float = Field(
        0.05, ge=0, description="Filled points may lie this far (m) outside the plane's extent."
    )
    drop_phantoms: bool = Field(
        True,
        description=(
            "Check every plane against the measured depth of a sample of views and drop "
            "phantoms (dense.plane_fill.max_seen_through, max_hidden)."
        ),
    )
    max_seen_through: float = Field(
        1.0,
        gt=0,
        description=(
            "Drop a plane when more measured points lie behind its extent than this multiple "
            "of those on it (a phantom plane floating in the room is seen through)."
        ),
    )
    max_hidden: float = Field(
        0.5,
        gt=0,
        description=(
            "Then drop a plane when more than this share of its points lie behind another "
            "kept plane (a phantom plane beneath the floor, from matches on a repeating "
            "carpet)."
        ),
    )
    shadow_gap_m: float = Field(
        0.1,
        ge=0,
        description="With drop_phantoms: of two parallel planes closer than this (m) whose "
        "extents overlap, the one fewer views support is a shadow of the other (views whose "
        "poses are slightly off put a wall a few cm in front of itself) and is dropped; 0: "
        "keep both.",
    )
    support_min_points: int = Field(
        50,
        ge=1,
        description="A view supports a plane when this many of its measured pixels (every "
        "4th row and column) lie on it.",
    )
    cull_behind: bool = Field(
        True,
        description=(
            "Remove measured depth that lies behind a plane's extent along its ray (matches "
            "through the floor on a repeating texture)."
        ),
    )
    seed: int = Field(0, description="Seed of the point sampling and RANSAC.")


class DenseConfig(Settings):
    """Settings of the dense stage: undistortion, view selection, depth estimation, fusion."""

    max_image_size: int = Field(
        640, ge=32, description="Longest side of the undistorted images, pixels (-1 not allowed)."
    )
    num_source_views: int = Field(4, ge=1, le=8, description="Source views per reference view.")
    min_shared_points: int = Field(
        10, ge=1, description="A source view must share at least this many sparse points."
    )
    min_triangulation_angle_deg: float = Field(
        1.0, ge=0, description="Minimum median triangulation angle to a source view, degrees."
    )
    full_angle_deg: float = Field(
        10.0,
        gt=0,
        description="Source selection: a source's shared sparse points count fully when their "
        "median triangulation angle reaches this (degrees), and by the square of the angle's "
        "share below it. Turn-in-place circles put neighbours 1-2 cm apart, where a pose "
        "error of 2 mm is a depth error of several per cent.",
    )
    skip_isolated_views: bool = Field(
        True,
        description="Leave out (with a warning naming them) views that share no usable overlap "
        "with any other view; false: fail instead. A campaign's goal photos can look at what "
        "little else saw, so leaving them out is the default.",
    )
    max_views: int = Field(
        0, ge=0, description="Reference views for which depth is computed (0 = all registered)."
    )
    depth_margin: float = Field(
        0.25, ge=0, description="Depth range = sparse-point depth percentiles widened by this."
    )
    backend: Literal["auto", "taichi", "colmap_cuda"] = Field(
        "auto",
        description="Depth backend: auto uses pycolmap.patch_match_stereo when pycolmap has "
        "CUDA, else the taichi PatchMatch.",
    )
    taichi_arch: Literal["auto", "cpu", "gpu"] = Field(
        "auto", description="Taichi arch: auto tries CUDA, then Vulkan, then CPU."
    )
    num_threads: int = Field(
        -1,
        description="CPU cores the stage uses (-1 = all): where taichi runs on the CPU, this "
        "many worker processes estimate, filter and plane-fill whole views, taichi on one "
        "thread each (the maps do not depend on the count; 1: all in the stage's process); "
        "on a GPU the stage is one process. Also fusion's threads.",
    )
    patchmatch: PatchMatchConfig = Field(default_factory=PatchMatchConfig)
    fusion_min_num_pixels: int = Field(
        2,
        ge=1,
        description="Fusion: minimum consistent pixels for a fused point (2: seen alike by "
        "two views; the top of a wall or a ceiling strip is often seen by only two).",
    )
    fusion_max_reproj_error: float = Field(
        2.0, gt=0, description="Fusion: maximum reprojection error, pixels."
    )
    fusion_max_depth_error: float = Field(
        0.01, gt=0, description="Fusion: maximum relative depth error (fraction)."
    )
    fusion_max_normal_error_deg: float = Field(
        10.0, gt=0, description="Fusion: maximum normal angle difference, degrees."
    )
    plane_fill: PlaneFillConfig = Field(default_factory=PlaneFillConfig)
    poisson_mesh: bool = Field(False, description="Also write a Poisson mesh of the fused cloud.")
    poisson_depth: int = Field(9, ge=5, le=12, description="Octree depth of the Poisson mesh.")
    plots: bool = Field(True, description="Write renders of the cloud and a depth/normal mosaic.")
