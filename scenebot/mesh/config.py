"""Settings of the mesh stage (``mesh:`` in config.yaml)."""

from __future__ import annotations

from pydantic import Field

from scenebot.settings import Settings


class VolumeConfig(Settings):
    """The 3-D free space of a person's photos (``robot: photos``; ``mesh.volume``): the space
    the photos saw through is empty (:mod:`scenebot.mesh.volume`)."""

    voxel_m: float = Field(
        0.05, gt=0.0, description="Voxel edge of the free-space grid (m, map units)."
    )
    max_voxels: int = Field(
        4_000_000,
        ge=1000,
        description="The grid over the cameras and points holds at most this many voxels "
        "(count): a larger scene gets larger voxels (logged and written to freespace.json).",
    )
    min_rays: int = Field(
        2,
        ge=1,
        description="A voxel is free when at least this many lines of sight (camera to an "
        "observed 3D point of the map) cross it (count): one stray ray (a wrong match) frees "
        "nothing.",
    )
    clearance_m: float = Field(
        0.1,
        ge=0.0,
        description="Voxels whose centre is this close (m) to a 3D point of the map or a mesh "
        "vertex are not free: a camera held there would touch the surface.",
    )
    min_voxels: int = Field(
        200,
        ge=1,
        description="A free space of fewer voxels is degenerate, an error (count): too few "
        "lines of sight to know where a person can stand.",
    )


class MeshConfig(Settings):
    """Poisson mesh of the sparse map and the free space cut from it (``mesh`` stage)."""

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
        "mesh.freespace.ray_coverage).",
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
    volume: VolumeConfig = Field(
        default_factory=VolumeConfig,
        description="robot: photos: the 3-D free space the photos saw through (in place of "
        "the robot's cut at the camera plane).",
    )
