"""The typed configuration: the single source of truth for every setting.

``config.yaml`` is validated against :class:`Config` when the workflow starts (and by every
CLI command). The JSON schema used by ``snakemake.utils.validate``
(``scenebot/config.schema.json``) is generated from this module with
``scenebot schema --write``; a test keeps the two in sync.

This module must stay light to import: the Snakefile loads it at every start.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from scenebot.dense.config import DenseConfig
from scenebot.evaluate.config import EvaluateConfig
from scenebot.localize.config import LocalizeConfig
from scenebot.plan.config import PlanConfig
from scenebot.robot.nxt.config import EmulatorConfig, NxtConfig
from scenebot.score.config import GoalsConfig, MeshConfig, ScoreConfig
from scenebot.sfm.config import SfmConfig
from scenebot.tour.config import TourConfig

SCHEMA_PATH = Path(__file__).with_name("config.schema.json")


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=True)


class StartPose(_Model):
    """Robot start pose in the world frame (m, degrees counter-clockwise from +x)."""

    x: float
    y: float
    theta_deg: float = 0.0


class WorldConfig(_Model):
    """The simulated world: a built-in scene or a textured mesh file."""

    builtin: Literal["office", "flat"] | None = Field(
        "office", description="Built-in scene generator; null when `file` is set."
    )
    file: Path | None = Field(
        None,
        description="Textured mesh scene (OBJ+MTL, PLY with UVs, glTF/GLB), metres, z up.",
    )
    seed: int = Field(7, description="Seed of the built-in scene generator.")
    floor_z: float | None = Field(
        None, description="Floor height (m); null: 0 for built-in scenes, detected for files."
    )
    start: StartPose | None = Field(None, description="Start pose; null: the scene's default.")

    @model_validator(mode="after")
    def _one_source(self) -> WorldConfig:
        if (self.builtin is None) == (self.file is None):
            raise ValueError(
                "set exactly one of world.builtin (allowed: 'office', 'flat') and world.file "
                "(a path to an OBJ, PLY or GLB scene)"
            )
        return self


class CameraConfig(_Model):
    """The robot's camera."""

    width: int = Field(640, ge=32, le=4096, description="Image width (px).")
    height: int = Field(480, ge=24, le=4096, description="Image height (px).")
    hfov_deg: float = Field(60.0, gt=10, lt=150, description="Horizontal field of view (deg).")
    height_m: float = Field(0.35, gt=0, description="Height of the optical centre (m).")
    forward_offset_m: float = Field(
        0.10, description="Camera ahead of the rotation axis (m): baselines in circles."
    )
    lateral_offset_m: float = Field(0.0, description="Camera left of the robot axis (m).")
    pitch_deg: float = Field(0.0, ge=-45, le=45, description="Upward tilt (deg).")
    sensor_width_mm: float = Field(5.76, gt=0, description="Sensor width for EXIF (mm).")
    jpeg_quality: int = Field(92, ge=50, le=100)
    antialias: bool = Field(True, description="Supersample geometric edges.")
    noise_sigma: float = Field(1.5, ge=0, description="Sensor noise (8-bit levels).")


class BodyConfig(_Model):
    """Robot body and drive train."""

    radius_m: float = Field(0.15, gt=0, description="Circular footprint radius (m).")
    height_m: float = Field(0.40, gt=0, description="Robot height (m): collision band top.")
    clearance_m: float = Field(0.01, ge=0, description="Collision band bottom above floor.")
    wheel_radius_m: float = Field(0.028, gt=0)
    wheel_base_m: float = Field(0.16, gt=0, description="Distance between the wheels (m).")
    max_wheel_speed_deg_s: float = Field(720.0, gt=0, description="Wheel speed at power 100.")
    drive_speed_deg_s: float = Field(360.0, gt=0, description="Wheel speed when driving.")
    turn_speed_deg_s: float = Field(240.0, gt=0, description="Wheel speed when turning.")


class SlipConfig(_Model):
    """Wheel slip: true motion = commanded x (1 - slip + noise); mostly on turns."""

    drive: float = Field(0.02, ge=0, lt=1, description="Mean slip when driving straight.")
    drive_noise: float = Field(0.01, ge=0, description="Std of the drive slip.")
    turn: float = Field(0.08, ge=0, lt=1, description="Mean slip when turning in place.")
    turn_noise: float = Field(0.03, ge=0, description="Std of the turn slip.")
    heading_drift_deg_per_m: float = Field(
        1.0, ge=0, description="Std of heading drift when driving straight (deg per m)."
    )


class SensorConfig(_Model):
    """Compass, ultrasonic rangefinder, bumpers, stall detection."""

    compass_noise_deg: float = Field(1.0, ge=0)
    compass_offset_deg: float = Field(
        0.0, description="Magnetic north relative to the world +x axis (deg, CCW)."
    )
    ultrasonic_cone_deg: float = Field(30.0, gt=0, le=90, description="Full cone angle.")
    ultrasonic_max_m: float = Field(2.55, gt=0, le=2.55)
    ultrasonic_noise_cm: float = Field(1.0, ge=0)
    ultrasonic_height_m: float = Field(0.15, gt=0)
    ultrasonic_max_incidence_deg: float = Field(
        60.0, gt=0, le=90, description="No echo from surfaces hit more obliquely than this."
    )
    bumper_arc_deg: float = Field(
        120.0, gt=0, le=180, description="Front and rear bumpers each cover this arc."
    )
    bumper_z_min_m: float = Field(0.02, ge=0)
    bumper_z_max_m: float = Field(0.12, gt=0)
    stall_window_s: float = Field(0.3, gt=0, description="Stall: no wheel progress for this.")
    stall_min_progress_deg: float = Field(3.0, gt=0)


class SimConfig(_Model):
    """The simulated robot."""

    camera: CameraConfig = CameraConfig()
    body: BodyConfig = BodyConfig()
    slip: SlipConfig = SlipConfig()
    sensors: SensorConfig = SensorConfig()
    dt_s: float = Field(0.01, gt=0, le=0.1, description="Physics time step (s).")
    photo_time_s: float = Field(1.5, ge=0, description="Simulated time per photo (s).")


class ExplorationConfig(_Model):
    """Round 0: random exploration (paper IV.A)."""

    photos: int = Field(100, ge=1, description="Photos to take in round 0.")
    circle_step_deg: float = Field(10.0, gt=0, le=90, description="Turn between photos.")
    drive_min_m: float = Field(0.4, gt=0)
    drive_max_m: float = Field(1.5, gt=0)
    backup_m: float = Field(0.12, gt=0, description="Back-up distance after a bump/stall.")
    escape_turn_min_deg: float = Field(60.0, ge=0, le=180)
    escape_turn_max_deg: float = Field(180.0, ge=0, le=180)
    max_escapes: int = Field(6, ge=1, description="Bumps per leg before starting a circle.")

    @model_validator(mode="after")
    def _ranges(self) -> ExplorationConfig:
        if self.drive_max_m < self.drive_min_m:
            raise ValueError("exploration.drive_max_m must be >= exploration.drive_min_m")
        if self.escape_turn_max_deg < self.escape_turn_min_deg:
            raise ValueError(
                "exploration.escape_turn_max_deg must be >= exploration.escape_turn_min_deg"
            )
        return self


class FollowConfig(_Model):
    """Settings of path following."""

    node_reached_m: float = Field(
        0.15, gt=0, description="Switch to the next path node within this distance (m)."
    )
    goal_reached_m: float = Field(
        0.05, gt=0, description="The goal is reached within this distance (m) of a visual fix."
    )
    localize_every_m: float = Field(
        0.5, gt=0, description="Longest drive (m) between visual localizations."
    )
    localize_after_turn_deg: float = Field(
        20.0, ge=0, description="Localize after a turn larger than this (deg)."
    )
    min_turn_deg: float = Field(
        2.0, ge=0, description="Heading errors below this (deg) are not corrected."
    )
    max_obstacles: int = Field(
        5, ge=1, description="Give up on a goal at this many bumps/stalls (the paper's k)."
    )
    backup_m: float = Field(0.12, gt=0, description="Back up this far (m) after a bump/stall.")
    sidestep_m: float = Field(
        0.25,
        ge=0,
        description="Then drive this far (m) off the path, at 90 deg, before replanning.",
    )
    obstacle_radius_m: float = Field(
        0.35,
        ge=0,
        description="A bump marks a disk of this radius (m) on the planner's grid as an "
        "obstacle: the unseen object's likely extent plus the robot's radius.",
    )
    contact_distance_m: float = Field(
        0.25, ge=0, description="Distance (m) ahead of the robot's axis where a bump is marked."
    )
    retrace_clear_m: float = Field(
        1.0,
        ge=0,
        description="After giving up on a goal, drive the motions that brought the robot "
        "there backwards, latest first, until it stands this far (m, by odometry) from where "
        "it gave up: it leaves by the way it came, through space it has driven. 0: off.",
    )
    retrace_max_m: float = Field(
        3.0, ge=0, description="Drive at most this far (m) when retracing."
    )
    max_localize_retries: int = Field(
        8,
        ge=0,
        description="Failed localizations at the goal before accepting odometry (with "
        "retry_turn_deg 40, eight retries look all around).",
    )
    confirm_m: float = Field(
        0.06,
        ge=0,
        description="A goal counts as reached on a fix only when a second fix from the same "
        "spot (after a turn in place: another view of the map) agrees with it within this "
        "distance (m); without one within max_localize_retries attempts the goal is accepted "
        "and reported unconfirmed. 0: one fix is enough.",
    )
    retry_turn_deg: float = Field(
        40.0,
        ge=0,
        description="Before retrying a failed localization at the goal, turn in place by "
        "this angle (deg), sweeping around (small turns slip little); 0: back up "
        "retry_move_m instead.",
    )
    retry_move_m: float = Field(
        0.08, gt=0, description="Back-up distance (m) before a retry when retry_turn_deg is 0."
    )
    max_motions: int = Field(
        120, ge=1, description="Motion commands per goal at most (then the goal is abandoned)."
    )
    camera_forward_m: float = Field(
        0.1,
        description="Camera centre ahead of the robot's rotation axis (m); unset in a "
        "campaign config: sim.camera.forward_offset_m (the camera mount).",
    )
    camera_left_m: float = Field(
        0.0,
        description="Camera centre left of the robot's rotation axis (m); unset in a "
        "campaign config: sim.camera.lateral_offset_m.",
    )
    gate_m: float = Field(
        0.5,
        ge=0,
        description="A fix farther than gate_m + gate_per_m * (distance driven since the last "
        "fix) from the odometry prediction is rejected (repeated textures can give confident "
        "wrong poses), unless the next fix agrees with it.",
    )
    gate_per_m: float = Field(0.25, ge=0, description="See gate_m (m per m driven).")
    gate_deg: float = Field(
        25.0, ge=0, description="A fix whose heading differs more (deg) from odometry is rejected."
    )
    compass_gate_deg: float = Field(
        45.0,
        ge=0,
        description="A fix whose heading differs more (deg) from the compass is rejected "
        "outright, even when a second fix agrees: the map's x axis is compass heading 0, and "
        "a repeated texture seen from the opposite side gives confident, mutually agreeing "
        "fixes about 180 deg off. 0: no compass check.",
    )
    turn_to_goal_heading: bool = Field(
        True, description="At the goal, turn to the goal's heading when it has one."
    )
    compass_std_deg: float = Field(
        2.0,
        ge=0,
        description="Between visual fixes the heading is dead-reckoned from odometry and "
        "corrected by the compass after every motion (a 1-D Kalman filter; the map's x axis "
        "is compass heading 0): this is the compass reading's standard deviation (deg). A "
        "reading beyond 3 sigma of the prediction is ignored. 0: odometry alone (a map "
        "whose heading is not from the compass, sfm.use_compass false).",
    )
    turn_slip_std: float = Field(
        0.1,
        ge=0,
        description="Standard deviation of a turn's odometry angle, relative to the turn "
        "(wheels slip on turns in place; the simulator's slip is 8 +- 3 %).",
    )
    heading_drift_deg_per_m: float = Field(
        1.0, ge=0, description="Standard deviation of heading drift per metre driven (deg)."
    )


class AdaptiveConfig(_Model):
    """Adaptive capture (rounds >= 1): drive to the goals of the previous round's map and take
    the missing photos there."""

    pattern: Literal["fan", "circle"] = Field(
        "fan",
        description="Photos at a goal: `fan`: the goal heading and fan_photos - 1 more, "
        "fan_step_deg apart, centred on it; `circle`: circle_photos evenly around.",
    )
    fan_photos: int = Field(5, ge=1, description="Photos per goal with pattern `fan`.")
    fan_step_deg: float = Field(
        15.0, gt=0, le=90, description="Heading step between fan photos (deg)."
    )
    circle_photos: int = Field(12, ge=3, description="Photos per goal with pattern `circle`.")
    max_photos: int = Field(
        60, ge=1, description="Photo budget of one adaptive round (photos at goals)."
    )
    localize_photos: bool = Field(
        True,
        description="Localize every goal photo against the map and log the estimate (it "
        "guides the next map's pair selection).",
    )
    replace_abandoned: bool = Field(
        True,
        description="When the robot gives up on a goal on the way (follow.max_obstacles, no "
        "route left), it drives to the next unused backup goal of goals.json instead "
        "(goals.backups), so the round still takes its photos.",
    )


class PhotosConfig(_Model):
    """Bring-your-own photos (``robot: photos``)."""

    folder: Path | None = Field(
        None, description="Folder of JPEGs (not recursive) that make round 0; never modified."
    )


class Config(_Model):
    """A scenebot campaign."""

    scene: str = Field(
        "office",
        pattern=r"^[A-Za-z0-9_.-]+$",
        description="Name of the campaign: results go to results/<scene>/.",
    )
    robot: Literal["sim", "nxt", "nxt-emulated", "photos"] = Field(
        "sim",
        description=(
            "Robot backend: the simulator, a LEGO NXT on a serial port (nxt.port), the NXT "
            "driver against the brick emulator on a pseudo-terminal backed by the simulator, "
            "or `photos`: no robot, round 0 is the folder of JPEGs in photos.folder."
        ),
    )
    seed: int = Field(1, description="Seed of the robot's noise and exploration choices.")
    max_rounds: int = Field(
        7,
        ge=1,
        description="Capture rounds at most: round 0 (exploration) and max_rounds - 1 "
        "adaptive rounds; the campaign stops earlier when a round's goals.json says complete "
        "(goals.complete_threshold_deg, goals.min_score_gain). 100 round-0 photos and 25 a "
        "round stay within 250 (the photo budget of issue 9 is 260). The office campaign of "
        "2026-11-26 measured 83.3% dense completeness at 2 cm after 5 rounds (200 photos) "
        "and 87.2% after 7 (245).",
    )
    world: WorldConfig = WorldConfig()
    sim: SimConfig = SimConfig()
    exploration: ExplorationConfig = ExplorationConfig()
    photos: PhotosConfig = PhotosConfig()
    nxt: NxtConfig = NxtConfig()
    nxt_emulator: EmulatorConfig = EmulatorConfig()
    sfm: SfmConfig = SfmConfig()
    mesh: MeshConfig = MeshConfig()
    score: ScoreConfig = ScoreConfig()
    goals: GoalsConfig = GoalsConfig()
    plan: PlanConfig = PlanConfig()
    localize: LocalizeConfig = LocalizeConfig()
    follow: FollowConfig = FollowConfig()
    adaptive: AdaptiveConfig = AdaptiveConfig()
    dense: DenseConfig = DenseConfig()
    tour: TourConfig = TourConfig()
    evaluate: EvaluateConfig = EvaluateConfig()

    @model_validator(mode="after")
    def _photos_folder(self) -> Config:
        if self.robot == "photos" and self.photos.folder is None:
            raise ValueError("robot: photos needs photos.folder (a folder of JPEG photos)")
        return self

    @model_validator(mode="after")
    def _camera_mount(self) -> Config:
        """The camera mount is configured once (sim.camera); following and the map's scale
        (sfm.camera_offset_m) use it unless set explicitly."""
        cam, fol = self.sim.camera, self.follow
        update = {}
        if "camera_forward_m" not in fol.model_fields_set:
            update["camera_forward_m"] = cam.forward_offset_m
        if "camera_left_m" not in fol.model_fields_set:
            update["camera_left_m"] = cam.lateral_offset_m
        if not self.sfm.use_compass and "compass_std_deg" not in fol.model_fields_set:
            update["compass_std_deg"] = 0.0  # the map's x axis is not compass heading 0
        if update and any(getattr(fol, k) != v for k, v in update.items()):
            object.__setattr__(self, "follow", FollowConfig(**{**fol.model_dump(), **update}))
        # the map's metric scale comes from circles of photos around the rotation axis
        offset = math.hypot(cam.forward_offset_m, cam.lateral_offset_m)
        if (
            self.robot != "photos"
            and offset > 0
            and "camera_offset_m" not in self.sfm.model_fields_set
            and self.sfm.camera_offset_m != offset
        ):
            sfm = SfmConfig(**{**self.sfm.model_dump(), "camera_offset_m": offset})
            object.__setattr__(self, "sfm", sfm)
        return self

    def round_limit(self) -> int:
        """Rounds the campaign runs at most: ``max_rounds``, or 1 for ``robot: photos``
        (a folder of photos is round 0, and no robot can take more)."""
        return 1 if self.robot == "photos" else self.max_rounds

    def camera_mount(self) -> tuple[float, float]:
        """The camera centre (forward, left) of the robot's rotation axis (m)."""
        return self.sim.camera.forward_offset_m, self.sim.camera.lateral_offset_m


# ---------------------------------------------------------------------------- loading
class ConfigError(ValueError):
    """An invalid configuration; the message names each bad key and what is allowed."""


def _format_errors(exc: ValidationError, source: str) -> str:
    lines = [f"invalid configuration in {source}:"]
    for err in exc.errors():
        loc = ".".join(str(p) for p in err["loc"] if not str(p).startswith("function-after"))
        msg = err["msg"]
        if err["type"] == "extra_forbidden":
            msg = "unknown key (check its spelling; `scenebot schema` lists all keys)"
        elif err["type"] == "literal_error":
            allowed = err.get("ctx", {}).get("expected", "")
            msg = f"got {err.get('input')!r}; allowed values: {allowed}"
        lines.append(f"  - {loc or '(top level)'}: {msg}")
    return "\n".join(lines)


def validate_config(data: dict[str, Any] | None, source: str = "config") -> Config:
    """Validate a config mapping.

    Raises:
        ConfigError: with one line per bad key naming it and the allowed values.
    """
    try:
        return Config.model_validate(data or {})
    except ValidationError as exc:
        raise ConfigError(_format_errors(exc, source)) from None


def load_config(path: Path | str) -> Config:
    """Read and validate a YAML config file."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"config file {path} not found (copy config.yaml from the repository)")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML: {exc}") from None
    return validate_config(data, str(path))


def json_schema() -> dict[str, Any]:
    """The JSON schema of :class:`Config` (what ``config.schema.json`` holds)."""
    schema = Config.model_json_schema(mode="validation")
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", **schema}


def write_schema(path: Path = SCHEMA_PATH) -> Path:
    path.write_text(json.dumps(json_schema(), indent=2, sort_keys=True) + "\n")
    return path


def section_json(cfg: Config, *keys: str) -> str:
    """The named top-level sections of ``cfg`` as canonical JSON (for Snakemake params)."""
    dump = cfg.model_dump(mode="json")
    return json.dumps({k: dump[k] for k in keys}, sort_keys=True, separators=(",", ":"))


def from_sections(text: str) -> Config:
    """Rebuild a :class:`Config` from :func:`section_json` output (other sections default)."""
    return validate_config(json.loads(text), "stage parameters")
