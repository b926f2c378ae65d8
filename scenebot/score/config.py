"""Settings of the score stage (``score:`` in config.yaml)."""

from __future__ import annotations

import math
from typing import Literal

from pydantic import Field, field_validator

from scenebot.settings import Settings


class PersonConfig(Settings):
    """Candidates of a person's camera (``robot: photos``; ``score.person``): six degrees of
    freedom in the 3-D free space, at the heights and tilts a person holds a camera."""

    heights_m: list[float] = Field(
        default_factory=lambda: [-0.6, 0.4],
        min_length=2,
        max_length=2,
        description="Lowest and highest camera height (m, map units) relative to the photos' "
        "median camera height: crouching to arms raised.",
    )
    pitch_deg: list[float] = Field(
        default_factory=lambda: [-45.0, 45.0],
        min_length=2,
        max_length=2,
        description="Lowest and highest camera tilt (degrees, up positive, each inside "
        "(-90, 90)); yaw is free, roll 0.",
    )

    @field_validator("heights_m")
    @classmethod
    def _heights(cls, v: list[float]) -> list[float]:
        if not all(math.isfinite(h) for h in v) or v[0] > v[1]:
            raise ValueError(f"{v}: two finite heights, lowest first, e.g. [-0.6, 0.4]")
        return v

    @field_validator("pitch_deg")
    @classmethod
    def _pitch(cls, v: list[float]) -> list[float]:
        if not (-90.0 < v[0] <= v[1] < 90.0):
            raise ValueError(f"{v}: lowest first, both inside (-90, 90), e.g. [-45, 45]")
        return v


class ScoreConfig(Settings):
    """Candidate viewpoints and the rendering-quality score (``score`` stage)."""

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
    person: PersonConfig = Field(
        default_factory=PersonConfig,
        description="robot: photos: candidates of a person's camera (6 degrees of freedom).",
    )
