"""Settings of the ground-truth evaluation (simulated scenes, or photos with reference cameras).

Kept free of heavy imports: the workflow loads every stage's config at start.
"""

from __future__ import annotations

from pathlib import Path

from pydantic import Field, field_validator

from scenebot.settings import Settings


class EvaluateConfig(Settings):
    """The evaluation of a round against the simulator's true scene (evaluation only).

    The observable surface (what completeness counts) is the part of the true mesh that a
    camera at the robot's camera height sees from some reachable pose; reachable poses are
    sampled on a grid over the free space connected to the start (the simulator's obstacle
    map, robot radius), each with several headings.
    """

    grid_step_m: float = Field(
        0.25, gt=0.01, description="Spacing (m) of the robot positions sampled in free space."
    )
    headings: int = Field(
        8, ge=1, le=72, description="Camera headings per sampled position (evenly spaced)."
    )
    sample_spacing_m: float = Field(
        0.02,
        gt=0.001,
        description="Mean spacing (m) of the points sampled on the true surface (each "
        "triangle gets at least one, weighted by its area).",
    )
    max_range_m: float | None = Field(
        None,
        gt=0,
        description="Surface farther than this (m) from the camera is not seen; null: no limit.",
    )
    max_incidence_deg: float = Field(
        85.0,
        gt=0,
        le=90,
        description="Surface seen more obliquely than this (deg from its normal) is not "
        "counted as seen (90: any angle).",
    )
    thresholds_m: list[float] = Field(
        [0.01, 0.02, 0.05], description="Distances (m) of accuracy and completeness."
    )
    max_cloud_points: int = Field(
        20_000_000,
        ge=1000,
        description="A denser fused cloud is randomly subsampled (seeded) to this many points "
        "(a memory guard). Subsampling thins the sparse parts of a cloud (ceiling, far walls) "
        "below the distance thresholds and so understates completeness: the office campaign "
        "of 2026-11-26, a 3.9-million-point cloud, measures 82.7% at 2 cm subsampled to 2 "
        "million and 87.2% whole (accuracy 97.4% either way).",
    )
    seed: int = Field(
        0, description="Seed of the surface sampling, cloud subsampling and validity draws."
    )
    validity_candidates: int = Field(
        200,
        ge=0,
        description="Score validity: random scored candidates of the validity round rendered "
        "by ULR and by the simulator (0: no study).",
    )
    validity_round: int = Field(
        0, ge=0, description="Score validity: the round whose map, photos and scores are used."
    )
    validity_width: int = Field(
        320, ge=16, description="Score validity: width of the compared renders (pixels)."
    )
    validity_height: int = Field(
        240, ge=12, description="Score validity: height of the compared renders (pixels)."
    )
    depth_maps: bool = Field(
        True,
        description="Evaluate every depth map of the dense workspace (measured and final) "
        "against the true depth along its pixel rays (final evaluation only).",
    )
    depth_rel_tol: float = Field(
        0.02, gt=0, lt=1, description="A depth is right within this share of the true depth."
    )
    depth_map_views: int = Field(
        0, ge=0, description="Evaluate at most this many depth maps, evenly spread (0: all)."
    )
    plots: bool = Field(True, description="Write the PNG pictures.")

    # --- bring-your-own photos (robot: photos) ---------------------------------------------
    reference_cameras: Path | None = Field(
        None,
        description="robot: photos: the photos' true cameras, read by the evaluation only "
        "(never by a decision): a Middlebury `*_par.txt` (`name k11..k33 r11..r33 t1 t2 t3` "
        "per line, world to camera), a COLMAP model folder (cameras, images), or a scenebot "
        "capture log.jsonl with true poses. Photos are matched by file name. The evaluation "
        "then fits the map to these cameras (a robust similarity) and reports the "
        "camera-centre errors in their units.",
    )
    reference_world: bool = Field(
        False,
        description="robot: photos: the photos were taken in the configured `world` (a "
        "simulated scene, in the frame of evaluate.reference_cameras): the dense cloud is "
        "evaluated against its observable surface as for a simulated robot.",
    )
    reference_bbox: list[list[float]] | None = Field(
        None,
        description="robot: photos of an object: its bounding box [[x0, y0, z0], [x1, y1, z1]] "
        "in the frame of evaluate.reference_cameras; the evaluation reports the share of the "
        "dense points inside it.",
    )

    @field_validator("reference_bbox")
    @classmethod
    def _box(cls, v: list[list[float]] | None) -> list[list[float]] | None:
        if v is None:
            return v
        if (
            len(v) != 2
            or any(len(c) != 3 for c in v)
            or any(a >= b for a, b in zip(*v, strict=True))
        ):
            raise ValueError(
                "evaluate.reference_bbox must be [[x0, y0, z0], [x1, y1, z1]] with x0 < x1, "
                f"y0 < y1, z0 < z1; got {v}"
            )
        return v

    @field_validator("thresholds_m")
    @classmethod
    def _positive(cls, v: list[float]) -> list[float]:
        if not v or any(t <= 0 for t in v):
            raise ValueError("evaluate.thresholds_m must be a non-empty list of positive metres")
        return sorted(v)
