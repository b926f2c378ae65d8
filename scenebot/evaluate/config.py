"""Settings of the ground-truth evaluation (simulated scenes, or photos with reference cameras).

Kept free of heavy imports: the workflow loads every stage's config at start.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Literal

from pydantic import Field, field_validator, model_validator

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
    cache_dir: str | None = Field(
        None,
        description="Folder of the cache shared by campaigns of the same scene (the observable "
        "surface, a file per scene and settings named by their hash): the suite's scenes, "
        "their baselines and every campaign of a scene compute it once. null: the environment "
        "variable SCENEBOT_CACHE if set, else $XDG_CACHE_HOME/scenebot (~/.cache/scenebot); "
        "'' (here or in SCENEBOT_CACHE): no shared cache. Where it lives changes no result: "
        "it is not among the rules' parameters, so changing it re-runs nothing.",
    )

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

    def cache_folder(self) -> Path | None:
        """The shared cache's folder (absolute), or None when the cache is off.

        ``cache_dir`` if set, else ``$SCENEBOT_CACHE`` if set, else ``$XDG_CACHE_HOME/scenebot``
        (``~/.cache/scenebot`` when XDG_CACHE_HOME is unset, empty or relative, as the XDG
        base directory specification says); an empty string at either of the first two
        turns the cache off. ``~`` is expanded; a relative path is taken from the current
        folder (the workflow's working directory in a rule).
        """
        value = self.cache_dir
        if value is None:
            value = os.environ.get("SCENEBOT_CACHE")
        if value is None:
            xdg = os.environ.get("XDG_CACHE_HOME", "")
            base = Path(xdg) if os.path.isabs(xdg) else Path("~/.cache").expanduser()
            return base / "scenebot"
        if value == "":
            return None
        return Path(value).expanduser().absolute()

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


class SuiteScene(Settings):
    """One scene of the suite: a built-in world with its seed, or a mesh file. Its campaign
    runs with the workflow's settings (config.yaml, --configfile, --config) in
    ``results/suite/<name>/``."""

    name: str = Field(
        pattern=r"^[A-Za-z][A-Za-z0-9_]*$",
        description="Name of the scene (letters, digits, _): results/suite/<name>/, a row of "
        "suite.json.",
    )
    builtin: Literal["office", "flat", "rooms"] | None = Field(
        None,
        description="Built-in world (world.builtin: rooms is one generated room per seed); "
        "null when `file` is set.",
    )
    file: Path | None = Field(
        None,
        description="Textured mesh scene (OBJ+MTL, PLY with UVs, glTF/GLB), metres, z up "
        "(world.file).",
    )
    seed: int = Field(7, description="Seed of the built-in scene generator (world.seed).")
    overrides: dict[str, Any] = Field(
        {},
        description="Settings of this scene's campaign only, as in config.yaml (e.g. "
        "`{world: {start: {x: 1.0, y: 2.0}}}`); the suite measures one set of settings, so "
        "keep these to what the scene needs to exist (a start pose, a floor height).",
    )

    @model_validator(mode="after")
    def _one_source(self) -> SuiteScene:
        if (self.builtin is None) == (self.file is None):
            raise ValueError(
                f"suite scene {self.name!r}: set exactly one of builtin (allowed: 'office', "
                "'flat', 'rooms') and file (a path to an OBJ, PLY or GLB scene)"
            )
        return self


def _default_scenes() -> list[SuiteScene]:
    rooms = [SuiteScene(name=f"rooms{k}", builtin="rooms", seed=k) for k in range(1, 7)]
    return [SuiteScene(name="office", builtin="office", seed=7),
            SuiteScene(name="flat", builtin="flat", seed=7), *rooms]  # fmt: skip


class SuiteConfig(Settings):
    """The scene suite (``snakemake --cores 2 suite``): per scene, the adaptive campaign, the
    random and frontier baselines at its photo budget and the final evaluation, summed up in
    ``results/suite/suite.{json,md,png}``."""

    scenes: list[SuiteScene] = Field(
        default_factory=_default_scenes,
        description="The scenes. Default: office, flat and the generated rooms of seeds 1-6 "
        "(rooms1..rooms6: a rectangle in paint, an L in wallpaper, a large rectangle in "
        "wallpaper, two rooms by a doorway, an L in wood panelling, two rooms by a corridor; "
        "scenebot/scene/rooms.py).",
    )
    baselines: list[Literal["random", "frontier"]] = Field(
        ["random", "frontier"],
        min_length=1,
        description="The baseline campaigns run at each campaign's photo budget (rule "
        "`baselines`: per suite scene, and `snakemake baselines` of one campaign): `random` "
        "(random exploration only) and `frontier` (the frontier chooser's goals). Each is a "
        "whole campaign more per scene; the suite's margins are over those run.",
    )

    @field_validator("scenes")
    @classmethod
    def _unique_names(cls, scenes: list[SuiteScene]) -> list[SuiteScene]:
        names = [s.name for s in scenes]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ValueError(f"suite scene names must differ; given twice: {', '.join(twice)}")
        return scenes

    @field_validator("baselines")
    @classmethod
    def _unique_baselines(cls, methods: list[str]) -> list[str]:
        if len(set(methods)) != len(methods):
            raise ValueError(f"suite.baselines names a baseline twice: {', '.join(methods)}")
        return methods
