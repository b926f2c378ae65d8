"""The typed configuration: the single source of truth for every setting.

``config.yaml`` is validated against :class:`Config` when the workflow starts (and by every
CLI command). The JSON schema used by ``snakemake.utils.validate``
(``scenebot/config.schema.json``) is generated from this module with
``scenebot schema --write``; a test keeps the two in sync.

This module must stay light to import: the Snakefile loads it at every start.
"""

from __future__ import annotations

import functools
import json
import math
from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import (
    BaseModel,
    Field,
    ValidationError,
    ValidationInfo,
    model_validator,
)

from scenebot.dense.config import DenseConfig
from scenebot.evaluate.config import EvaluateConfig, SuiteConfig
from scenebot.goals.config import GoalsConfig
from scenebot.guide.config import GuideConfig
from scenebot.localize.config import LocalizeConfig
from scenebot.mesh.config import MeshConfig
from scenebot.plan.config import PlanConfig
from scenebot.robot.nxt.config import EmulatorConfig, NxtConfig
from scenebot.robot.person_config import PersonSimConfig
from scenebot.score.config import ScoreConfig
from scenebot.settings import Settings
from scenebot.sfm.config import SfmConfig
from scenebot.tour.config import TourConfig

SCHEMA_PATH = Path(__file__).with_name("config.schema.json")


def _received(info: ValidationInfo, *sections: str) -> bool:
    """Whether a check across sections applies: always to a whole config; to stage
    parameters (:func:`from_sections`: a stage gets only the sections it reads) only when
    every section the check reads was received. The workflow checked the whole config."""
    received = (info.context or {}).get("sections")
    return received is None or all(s in received for s in sections)


class StartPose(Settings):
    """Robot start pose in the world frame (m, degrees counter-clockwise from +x)."""

    x: float
    y: float
    theta_deg: float = 0.0


class WorldConfig(Settings):
    """The simulated world: a built-in scene or a textured mesh file."""

    builtin: Literal["office", "flat", "rooms"] | None = Field(
        "office",
        description="Built-in scene generator (rooms: one generated room per seed); null "
        "when `file` is set.",
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
                "set exactly one of world.builtin (allowed: 'office', 'flat', 'rooms') and "
                "world.file (a path to an OBJ, PLY or GLB scene)"
            )
        return self


class CameraConfig(Settings):
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


class BodyConfig(Settings):
    """Robot body and drive train."""

    radius_m: float = Field(0.15, gt=0, description="Circular footprint radius (m).")
    height_m: float = Field(0.40, gt=0, description="Robot height (m): collision band top.")
    clearance_m: float = Field(0.01, ge=0, description="Collision band bottom above floor.")
    wheel_radius_m: float = Field(0.028, gt=0)
    wheel_base_m: float = Field(0.16, gt=0, description="Distance between the wheels (m).")
    max_wheel_speed_deg_s: float = Field(720.0, gt=0, description="Wheel speed at power 100.")
    drive_speed_deg_s: float = Field(360.0, gt=0, description="Wheel speed when driving.")
    turn_speed_deg_s: float = Field(240.0, gt=0, description="Wheel speed when turning.")


class SlipConfig(Settings):
    """Wheel slip: true motion = commanded x (1 - slip + noise); mostly on turns."""

    drive: float = Field(0.02, ge=0, lt=1, description="Mean slip when driving straight.")
    drive_noise: float = Field(0.01, ge=0, description="Std of the drive slip.")
    turn: float = Field(0.08, ge=0, lt=1, description="Mean slip when turning in place.")
    turn_noise: float = Field(0.03, ge=0, description="Std of the turn slip.")
    heading_drift_deg_per_m: float = Field(
        1.0, ge=0, description="Std of heading drift when driving straight (deg per m)."
    )


class SensorConfig(Settings):
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


class SimConfig(Settings):
    """The simulated robot."""

    camera: CameraConfig = CameraConfig()
    body: BodyConfig = BodyConfig()
    slip: SlipConfig = SlipConfig()
    sensors: SensorConfig = SensorConfig()
    dt_s: float = Field(0.01, gt=0, le=0.1, description="Physics time step (s).")
    photo_time_s: float = Field(1.5, ge=0, description="Simulated time per photo (s).")


class ExplorationConfig(Settings):
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


class FollowConfig(Settings):
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
    min_matchable_points: int = Field(
        10,
        ge=0,
        description="Before a localization photo, the map points the robot's pose estimate "
        "predicts it can match (in view, seen within score.match_angle_deg and a factor "
        "score.match_scale_ratio of distance of how the map's photos saw them, as for a "
        "goal); fewer than this and no photo is taken (logged as localize_skipped), the robot "
        "goes on dead reckoning. In the office 61% of the localization photos failed, with a "
        "median of 37 such points against 1,018 for the fixes; 10 skips 29% of the failures "
        "and 1% of the fixes. Only once the robot has had a fix this round; 0 = off.",
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
    override_min_turn_deg: float = Field(
        30.0,
        ge=0,
        description="A fix rejected by the gate is taken after all when the next fix agrees "
        "with it (the odometry prediction was wrong), but only when the robot turned by at "
        "least this much between the two (deg): two views of the same wall are not two "
        "pieces of evidence, a repeated texture fools both alike (the flat at 02ad37d: four "
        "such pairs after turns of 1-13 deg took fixes 2.4 m off; those after 22-138 deg "
        "were right). Default: half the 60 deg field of view. 0: any two agreeing fixes.",
    )
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


class AdaptiveConfig(Settings):
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


class PhotosConfig(Settings):
    """Bring-your-own photos (``robot: photos`` and ``robot: guided``)."""

    folder: Path | None = Field(
        None,
        description="Folder of photos (JPEG or PNG, suffixes in any case; not recursive) that "
        "make round 0; never modified. The same photo twice is used once.",
    )


ROBOT_SECTIONS: dict[str, tuple[str, ...]] = {
    "sim": ("world", "sim"),
    # the camera mount (sim.camera) places photos on the robot; no simulated world
    "nxt": ("sim", "nxt"),
    "nxt-emulated": ("world", "sim", "nxt", "nxt_emulator"),
    "photos": ("photos",),
    "guided": ("photos",),
    "person-sim": ("world", "sim", "person_sim"),
}
"""The config sections each ``robot:`` backend reads."""

GUIDED_EXHAUSTIVE_MAX_IMAGES = 250
"""sfm.exhaustive_max_images of a guided campaign unless set: a person's new photos have no
position to pair them by, so all pairs are matched up to the photo budget."""
PERSON_ROBOTS = ("photos", "guided", "person-sim")
"""The backends whose photos are a person's: six degrees of freedom, the person's frame."""
GUIDED_ROBOTS = ("guided", "person-sim")
"""The backends of guided rounds: a person takes the next round's photos from the guide page
and puts them in the round's inbox (``round_XXX/capture/inbox/``)."""


class Config(Settings):
    """A scenebot campaign."""

    scene: str = Field(
        "office",
        pattern=r"^[A-Za-z0-9_.-]+(/[A-Za-z0-9_.-]+)?$",
        description="Name of the campaign: results go to results/<scene>/ (one / makes a "
        "subfolder: the suite's campaigns are suite/<name>).",
    )
    robot: Literal["sim", "nxt", "nxt-emulated", "photos", "guided", "person-sim"] = Field(
        "sim",
        description=(
            "Robot backend: the simulator, a LEGO NXT on a serial port (nxt.port), the NXT "
            "driver against the brick emulator on a pseudo-terminal backed by the simulator, "
            "`photos`: no robot, round 0 is the folder of photos in photos.folder; `guided`: "
            "round 0 is that folder and every later round the photos a person puts in the "
            "round's inbox (round_XXX/capture/inbox/) following the previous round's guide "
            "page; `person-sim`: a simulated person in the simulated world takes them "
            "(person_sim)."
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
    person_sim: PersonSimConfig = PersonSimConfig()
    sfm: SfmConfig = SfmConfig()
    mesh: MeshConfig = MeshConfig()
    score: ScoreConfig = ScoreConfig()
    goals: GoalsConfig = GoalsConfig()
    guide: GuideConfig = GuideConfig()
    plan: PlanConfig = PlanConfig()
    localize: LocalizeConfig = LocalizeConfig()
    follow: FollowConfig = FollowConfig()
    adaptive: AdaptiveConfig = AdaptiveConfig()
    dense: DenseConfig = DenseConfig()
    tour: TourConfig = TourConfig()
    evaluate: EvaluateConfig = EvaluateConfig()
    suite: SuiteConfig = SuiteConfig()

    @model_validator(mode="after")
    def _photos_folder(self, info: ValidationInfo) -> Config:
        if not _received(info, "photos"):
            return self
        if self.robot in ("photos", "guided") and self.photos.folder is None:
            raise ValueError(
                f"robot: {self.robot} needs photos.folder (a folder of JPEG or PNG photos)"
            )
        return self

    @model_validator(mode="after")
    def _reference_for_photos(self, info: ValidationInfo) -> Config:
        ev = self.evaluate
        if not _received(info, "evaluate") or self.robot == "photos":
            return self
        if ev.reference_cameras is not None or ev.reference_world or ev.reference_bbox:
            raise ValueError(
                "evaluate.reference_cameras, reference_world and reference_bbox are for robot: "
                f"photos (a person's photos with known cameras); robot: {self.robot} logs the "
                "true poses itself: remove them"
            )
        return self

    @model_validator(mode="after")
    def _camera_mount(self, info: ValidationInfo) -> Config:
        """The camera mount is configured once (sim.camera); following and the map's scale
        (sfm.camera_offset_m) use it unless set explicitly."""
        if not _received(info, "sim"):
            return self  # stage parameters: the sections received hold the derived values
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
            not self.person_photos()
            and offset > 0
            and "camera_offset_m" not in self.sfm.model_fields_set
            and self.sfm.camera_offset_m != offset
        ):
            sfm = SfmConfig(**{**self.sfm.model_dump(), "camera_offset_m": offset})
            object.__setattr__(self, "sfm", sfm)
        return self

    @model_validator(mode="after")
    def _person_pairs(self, info: ValidationInfo) -> Config:
        """A guided round's photos have no position to choose their match partners by (no
        odometry, no localization, no compass): unless set, every pair is matched up to
        ``GUIDED_EXHAUSTIVE_MAX_IMAGES`` photos (the campaign's photo budget). The simulated
        person's walk spreads its camera heights by ``person_sim.height_std_m``: the sfm
        stage's eye-height plane (``sfm.person_height_std_m``) expects that unless set."""
        if not _received(info, "sfm"):
            return self
        sfm, update = self.sfm, {}
        if (
            self.guided_rounds()
            and "exhaustive_max_images" not in sfm.model_fields_set
            and sfm.exhaustive_max_images != GUIDED_EXHAUSTIVE_MAX_IMAGES
        ):
            update["exhaustive_max_images"] = GUIDED_EXHAUSTIVE_MAX_IMAGES
        if (
            self.robot == "person-sim"
            and _received(info, "person_sim")
            and "person_height_std_m" not in sfm.model_fields_set
            and sfm.person_height_std_m != self.person_sim.height_std_m
        ):  # the walk's heights spread as the simulated person holds the camera
            update["person_height_std_m"] = self.person_sim.height_std_m
        if update:
            object.__setattr__(self, "sfm", SfmConfig(**{**sfm.model_dump(), **update}))
        return self

    def robot_sections(self) -> tuple[str, ...]:
        """The config sections the configured robot reads (with ``exploration``, a capture's
        params): changing another robot's settings never re-takes a capture."""
        return ROBOT_SECTIONS[self.robot]

    def person_photos(self) -> bool:
        """Whether the photos are a person's (``photos``, ``guided``, ``person-sim``): six
        degrees of freedom, the person's frame, shots instead of a robot's goals."""
        return self.robot in PERSON_ROBOTS

    def guided_rounds(self) -> bool:
        """Whether rounds after the first are a person's guided rounds (``guided``,
        ``person-sim``): photos from the round's inbox, no robot to plan paths for."""
        return self.robot in GUIDED_ROBOTS

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


_NULLS = frozenset({"null", "Null", "NULL", "~"})
"""YAML's spellings of null, as text: nested ``--config`` values arrive as text (Snakemake
reads them with YAML's BaseLoader), ``world={builtin: null}`` as ``'null'``."""


def _model_of(annotation: Any) -> type[BaseModel] | None:
    """The model class in a field's annotation (``StartPose | None`` -> ``StartPose``)."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in getattr(annotation, "__args__", ()):
        if isinstance(arg, type) and issubclass(arg, BaseModel):
            return arg
    return None


def _example(loc: tuple) -> str:
    """``", e.g. <default>"`` for the field at ``loc`` (a right value to copy), or ``""``."""
    model: type[BaseModel] | None = Config
    default: Any = None
    for part in loc:
        if model is None or not isinstance(part, str) or part not in model.model_fields:
            return ""
        field = model.model_fields[part]
        model = _model_of(field.annotation)
        default = None if field.is_required() else field.get_default(call_default_factory=True)
    if default is None or isinstance(default, (bool, BaseModel)):
        return ""
    return f", e.g. {str(default)!r}" if isinstance(default, Path) else f", e.g. {default!r}"


_EXPECTED = {
    **dict.fromkeys(
        ("int_type", "int_parsing", "int_from_float", "int_parsing_size"), "a whole number"
    ),
    **dict.fromkeys(("float_type", "float_parsing", "finite_number"), "a number"),
    **dict.fromkeys(("bool_type", "bool_parsing"), "true or false"),
    **dict.fromkeys(("model_type", "model_attributes_type", "dict_type"), "a section"),
    "string_type": "text",
    "list_type": "a list",
    "path_type": "a path",
}


def _is_nan(value: Any) -> bool:
    if isinstance(value, str):
        return value.strip().lower() in ("nan", ".nan", "+nan", "-nan")
    return isinstance(value, float) and math.isnan(value)


def _message(err: dict) -> str:
    """One error of the typed model as ``got <value>; <what to write instead>``."""
    kind, loc, value = err["type"], err["loc"], err.get("input")
    if kind == "extra_forbidden":
        return "unknown key (check its spelling; `scenebot schema` lists all keys)"
    if kind == "missing":
        return "missing: this key is required here"
    if kind == "literal_error":
        return f"got {value!r}; allowed values: {err.get('ctx', {}).get('expected', '')}"
    if kind in ("value_error", "assertion_error"):
        return err["msg"].removeprefix("Value error, ").removeprefix("Assertion failed, ")
    if _is_nan(value):
        return f"got {value!r}; expected a number{_example(loc)}"
    expected = _EXPECTED.get(kind)
    if expected == "a section":
        return f"got {value!r}; expected a section of keys (a mapping)"
    if expected == "text":
        return f"got {value!r}; expected text{_example(loc)} (quote it)"
    if expected == "true or false":
        return f"got {value!r}; expected true or false"
    if expected is not None:
        return f"got {value!r}; expected {expected}{_example(loc)}"
    msg = err["msg"].replace("Input should be", "must be").replace("String should", "must")
    return f"got {value!r}; {msg}"


_UNION_TAGS = ("float", "int", "str", "bool", "none", "literal[")
"""How pydantic names the members of a union in an error's location (``camera_pitch_deg``'s
``float`` and ``literal['map']``): not keys of the configuration."""


def _key(loc: tuple) -> str:
    return ".".join(
        str(p)
        for p in loc
        if not str(p).startswith("function-after") and not str(p).startswith(_UNION_TAGS)
    )


def _report(problems: dict[str, str], source: str) -> ConfigError:
    """One line per bad key: ``  - <key>: <what is wrong and what to write>``."""
    lines = [f"invalid configuration in {source}:"]
    lines += [f"  - {key or '(top level)'}: {msg}" for key, msg in problems.items()]
    return ConfigError("\n".join(lines))


def _problems(exc: ValidationError) -> dict[str, str]:
    problems: dict[str, str] = {}
    for err in exc.errors():
        key = _key(err["loc"])
        msg = _message(err).removeprefix(f"{key}: ") if key else _message(err)
        if (
            key in problems
            and err["loc"][-1:] != ()
            and str(err["loc"][-1]).startswith(_UNION_TAGS)
        ):
            # another member of a union (a number or `map`): what else the key accepts
            problems[key] += "; or " + msg.split("; ", 1)[-1]
        problems.setdefault(key, msg)  # the first error of each key
    return problems


def _replaced(data: Any, loc: tuple, value: Any = None) -> Any:
    """A copy of ``data`` with the value at ``loc`` replaced by ``value``."""
    if not loc:
        return value
    if isinstance(data, dict):
        return {k: _replaced(v, loc[1:], value) if k == loc[0] else v for k, v in data.items()}
    if isinstance(data, list):
        return [_replaced(v, loc[1:], value) if i == loc[0] else v for i, v in enumerate(data)]
    return data


def _as_yaml(value: Any) -> Any:
    """Text as YAML reads it (``'12'`` -> 12, ``'null'`` -> None), else ``value``."""
    if not isinstance(value, str):
        return value
    try:
        read = yaml.safe_load(value)
    except yaml.YAMLError:
        return value
    return read if read is None or isinstance(read, (bool, int, float)) else value


def _nulls_as_none(data: Any, model: type[BaseModel] | None = None) -> Any:
    """``data`` with ``'null'`` (and YAML's other spellings, as text) made None where the key
    may be null: ``--config 'world={builtin: office, file: null}'`` gives ``'null'``."""
    model = Config if model is None else model
    if not isinstance(data, dict):
        return data
    out = {}
    for k, v in data.items():
        field = model.model_fields.get(k) if isinstance(k, str) else None
        if field is None:
            out[k] = v
        elif (
            isinstance(v, str)
            and v in _NULLS
            and type(None) in getattr(field.annotation, "__args__", ())
        ):
            out[k] = None
        elif isinstance(v, dict) and _model_of(field.annotation) is not None:
            out[k] = _nulls_as_none(v, _model_of(field.annotation))
        else:
            out[k] = v
    return out


def _typed(data: Any, context: dict | None) -> tuple[Config | None, dict[str, str]]:
    """The typed model of ``data``, or the problems (one message per key).

    Text where the text itself is not allowed is read once more as YAML would read it: nested
    ``--config`` values arrive as text (Snakemake reads them with YAML's BaseLoader), so
    ``world={builtin: null}`` gives ``'null'`` and ``neighbors: [4, 8]`` gives ``['4', '8']``.
    """
    data = _nulls_as_none(data)
    try:
        return Config.model_validate(data, context=context), {}
    except ValidationError as exc:
        first = exc
    patched, subs = data, {}
    for err in first.errors():
        loc = tuple(p for p in err["loc"] if _key((p,)))
        value = err.get("input")
        if isinstance(value, str) and _as_yaml(value) is not value:
            patched = _replaced(patched, loc, _as_yaml(value))
            subs[_key(loc)] = _message(err)
    if not subs:
        return None, _problems(first)
    try:
        return Config.model_validate(patched, context=context), {}
    except ValidationError as exc:
        problems = _problems(exc)
        return None, {k: subs.get(k, msg) for k, msg in problems.items()}


def _leaf_problems(raw: Any, normal: Any, loc: tuple = ()) -> dict[str, str]:
    """Values the model read leniently but wrongly: true/false where a number is expected
    (the model reads them as 1/0), and nan."""
    if isinstance(raw, dict) and isinstance(normal, dict):
        found: dict[str, str] = {}
        for k, v in raw.items():
            if k in normal:
                found |= _leaf_problems(v, normal[k], (*loc, k))
        return found
    if isinstance(raw, list) and isinstance(normal, list) and len(raw) == len(normal):
        found = {}
        for i, (a, b) in enumerate(zip(raw, normal, strict=True)):
            found |= _leaf_problems(a, b, (*loc, i))
        return found
    if isinstance(raw, bool) and not isinstance(normal, bool):
        what = "a whole number" if isinstance(normal, int) else "a number"
        return {_key(loc): f"got {raw!r}; expected {what}{_example(loc)}"}
    if isinstance(normal, float) and math.isnan(normal):
        return {_key(loc): f"got {raw!r}; expected a number{_example(loc)}"}
    return {}


def normalize_config(data: dict[str, Any], cfg: Config) -> dict[str, Any]:
    """``data`` (the keys a user gave) with each value as ``cfg`` read it: ``"12"`` for a
    whole number is 12, ``"false"`` for a switch is false, ``"null"`` is null. The workflow
    hands this to the JSON schema (and to its rules), so the schema never sees a value the
    typed model read as another type."""
    return _normalized(data, cfg.model_dump(mode="json"))


def _normalized(raw: Any, normal: Any) -> Any:
    if isinstance(raw, dict) and isinstance(normal, dict):
        return {k: _normalized(v, normal[k]) if k in normal else v for k, v in raw.items()}
    return raw if _same_kind(raw, normal) else normal


def _same_kind(raw: Any, normal: Any) -> bool:
    """Whether ``raw`` is already ``normal`` as JSON sees it (an int is a number): such a
    value is kept as written, so a config written right is handed on unchanged."""
    if isinstance(raw, bool) or isinstance(normal, bool):
        return type(raw) is type(normal) and raw == normal
    if isinstance(raw, (int, float)) and isinstance(normal, (int, float)):
        return raw == normal
    if isinstance(raw, list) and isinstance(normal, list):
        return len(raw) == len(normal) and all(map(_same_kind, raw, normal))
    return type(raw) is type(normal) and raw == normal


@functools.lru_cache(maxsize=1)
def _schema_validator():
    import jsonschema

    schema = json.loads(SCHEMA_PATH.read_text())
    return jsonschema.validators.validator_for(schema)(schema)


def _schema_problems(data: dict[str, Any]) -> dict[str, str]:
    """What the workflow's JSON schema (the file ``snakemake.utils.validate`` reads) says
    about ``data``, one line per key."""
    problems: dict[str, str] = {}
    for err in _schema_validator().iter_errors(data):
        key = ".".join(str(p) for p in err.absolute_path)
        problems.setdefault(
            key,
            f"got {err.instance!r}; the config schema says: {err.message} (the typed model "
            "accepts it: if scenebot/config.schema.json is stale, run `scenebot schema --write`)",
        )
    return problems


def validate_config(
    data: dict[str, Any] | None, source: str = "config", *, sections: Any = None
) -> Config:
    """Validate a config mapping as a YAML file or Snakemake's ``config`` gives it.

    Values are read by the type of their key (``photos: "12"`` is 12; nested ``--config``
    values, which Snakemake passes as text, too), then the values as read must pass the JSON
    schema the workflow validates with (:func:`normalize_config`): ``scenebot check-config``
    and the workflow accept and refuse the same files.

    Args:
        data: the mapping.
        source: where it came from, for the message.
        sections: stage parameters only (:func:`from_sections`): the top-level sections
            received; checks across sections apply only to those (a stage's config holds only
            the sections it reads, and the workflow checked the whole config).

    Raises:
        ConfigError: one line per bad key: ``  - <key>: got <value>; <what to write>``.
    """
    data = {} if data is None else data
    context = None if sections is None else {"sections": frozenset(sections)}
    cfg, problems = _typed(data, context)
    if cfg is None:
        raise _report(problems, source)
    normal = cfg.model_dump(mode="json")
    problems = _leaf_problems(data, normal)
    if not problems and sections is None:
        problems = _schema_problems(_normalized(data, normal))
    if problems:
        raise _report(problems, source)
    return cfg


def load_config(path: Path | str) -> Config:
    """Read and validate a YAML config file (see :func:`validate_config`).

    Raises:
        ConfigError: the file is missing, not YAML, not a mapping, or a value is wrong.
    """
    return validate_config(read_config_file(path), str(path))


def read_config_file(path: Path | str) -> dict[str, Any]:
    """The mapping of a YAML config file (empty: no keys), with a clear error naming it.

    Raises:
        ConfigError: the file is missing, not valid YAML, or not keys and values.
    """
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"config file {path} not found (copy config.yaml from the repository)")
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: not valid YAML: {exc}") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError(
            f"{path}: not a config file: expected keys and values (a YAML mapping such as "
            f"`scene: office`), got {type(data).__name__} {str(data)[:60]!r}"
        )
    return data


CONFIG_SUFFIXES = (".yaml", ".yml", ".json")


def check_config_files(paths: list[Path | str], results: Path | str = "results") -> None:
    """The files Snakemake read as ``--configfile``: each must look like a config file.

    Snakemake reads every word after ``--configfile`` as a config file, so
    ``--configfile my.yaml results/my/round_000/capture/log.jsonl`` reads the target too.
    A missing or unreadable one stops Snakemake before the workflow starts (with its own
    message); one it could read (a JSON result, say) is named here.

    Raises:
        ConfigError: naming the file and the order that works.
    """
    results = Path(results).resolve()
    for path in paths:
        path = Path(path)
        if path.resolve().is_relative_to(results):
            what = "a result of the workflow"
        elif path.suffix.lower() not in CONFIG_SUFFIXES:
            what = "its name does not end in .yaml, .yml or .json"
        else:
            continue
        here = Path.cwd().resolve()
        shown = path.resolve().relative_to(here) if path.resolve().is_relative_to(here) else path
        raise ConfigError(
            f"--configfile got {shown}, which is not a config file ({what}): Snakemake "
            "reads every word after --configfile as a config file. Give the targets first "
            "(snakemake --cores 2 <targets> --configfile my.yaml) or write "
            "--configfile=my.yaml"
        )


def json_schema() -> dict[str, Any]:
    """The JSON schema of :class:`Config` (what ``config.schema.json`` holds)."""
    schema = Config.model_json_schema(mode="validation")
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", **schema}


def write_schema(path: Path = SCHEMA_PATH) -> Path:
    path.write_text(json.dumps(json_schema(), indent=2, sort_keys=True) + "\n")
    return path


# Settings that say where files are kept, not what a stage computes: left out of the
# rules' parameters (section_json), so that changing them re-runs nothing. A rule that needs
# one passes it on its own (rule observable: evaluate.cache_dir as --cache-dir).
NOT_PARAMETERS: dict[str, set[str]] = {"evaluate": {"cache_dir"}}


def section_json(cfg: Config, *keys: str) -> str:
    """The named top-level sections of ``cfg`` as canonical JSON (for Snakemake params), less
    :data:`NOT_PARAMETERS`."""
    dump = cfg.model_dump(mode="json", exclude=NOT_PARAMETERS)
    return json.dumps({k: dump[k] for k in keys}, sort_keys=True, separators=(",", ":"))


def from_sections(text: str) -> Config:
    """Rebuild a :class:`Config` from :func:`section_json` output (other sections default;
    checks across sections apply only to the sections received)."""
    data = json.loads(text)
    return validate_config(data, "stage parameters", sections=data)
