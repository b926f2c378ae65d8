"""Settings of the simulated person (``robot: person-sim``, ``person_sim:`` in config.yaml)."""

from __future__ import annotations

import math

from pydantic import Field, field_validator

from scenebot.settings import Settings


class PersonSimConfig(Settings):
    """A simulated person with a camera in the simulated world (``robot: person-sim``): round
    0 is a walk along the room's walls taking photos at even spacing; later rounds walk to
    each shot of the previous round's guide, with a person's error, and put the photos in
    the next round's inbox as a person would."""

    perimeter_photos: int = Field(
        40, ge=3, description="Round 0: photos of the walk along the room's walls (count)."
    )
    perimeter_inset_m: float = Field(
        0.6,
        gt=0,
        description="Round 0: the walk keeps this far (m) from walls and furniture, facing "
        "into the room.",
    )
    eye_height_m: list[float] = Field(
        default_factory=lambda: [1.2, 1.8],
        min_length=2,
        max_length=2,
        description="The person's camera height when standing (m above the floor): drawn "
        "once per campaign (seed) uniformly from this range.",
    )
    lowest_m: float = Field(
        0.4, gt=0, description="Lowest camera height the person crouches to (m above the floor)."
    )
    reach_up_m: float = Field(
        0.3, ge=0, description="How far above eye height the person raises the camera (m)."
    )
    position_std_m: float = Field(
        0.2,
        ge=0,
        description="Standard deviation (m) of where the person stands, per horizontal axis "
        "(the shot's position as the person understands the guide, plus this).",
    )
    height_std_m: float = Field(
        0.05, ge=0, description="Standard deviation (m) of the camera height asked for."
    )
    heading_std_deg: float = Field(
        10.0, ge=0, description="Standard deviation (degrees) of the camera's heading."
    )
    pitch_std_deg: float = Field(
        5.0, ge=0, description="Standard deviation (degrees) of the tilt, around the one asked."
    )
    roll_std_deg: float = Field(
        2.0, ge=0, description="Standard deviation (degrees) of the camera's roll (0 asked)."
    )
    compass_std_deg: float | None = Field(
        10.0,
        ge=0,
        description="The phone records its orientation with each photo (the capture log's "
        "`orientation`: compass heading, and pitch and roll from its accelerometer), the "
        "heading with this standard deviation (deg; a phone's compass indoors: 5-15); null: "
        "a phone that records none.",
    )
    motion_drift: float | None = Field(
        0.01,
        ge=0,
        description="The phone tracks its own motion (visual-inertial odometry, as ARKit and "
        "ARCore do) and records each photo's camera pose in its session's frame (the capture "
        "log's `motion`; one session per round), drifting by this fraction of the distance "
        "walked (position, per axis; the heading as many radians per metre); null: a phone "
        "that records none. Phones drift 1-3% indoors.",
    )
    gravity_std_deg: float = Field(
        1.0, ge=0, description="Standard deviation (deg) of the phone's pitch and roll readings."
    )
    photos_per_shot: int = Field(
        1,
        ge=1,
        description="Photos the person takes at each shot, fan_step_deg apart in heading, "
        "centred on the shot's.",
    )
    fan_step_deg: float = Field(
        15.0, gt=0, le=90, description="Heading step between a shot's photos (degrees)."
    )
    clearance_m: float = Field(
        0.25,
        gt=0,
        description="The person's half width (m): a spot closer than this to furniture or "
        "walls (between 0.1 m and 1.5 m above the floor) cannot be stood on.",
    )
    reach_m: float = Field(
        0.5,
        ge=0,
        description="How far (m) the person holds the camera out from where it stands (over "
        "a desk or a sofa); a shot with no spot to stand on within this, or inside or behind "
        "furniture from there, is skipped.",
    )
    tape_photos: list[int] = Field(
        default_factory=lambda: [0, 5],
        min_length=2,
        max_length=2,
        description="Round 0: the person measures with a tape the distance between where it "
        "took these two photos (0-based indices of the walk) and writes it in the capture "
        "log: the map's metric scale (as sfm.known_distance).",
    )
    tape_std_m: float = Field(
        0.01, ge=0, description="Standard deviation (m) of the tape measurement."
    )

    @field_validator("eye_height_m")
    @classmethod
    def _heights(cls, v: list[float]) -> list[float]:
        if not (all(math.isfinite(h) for h in v) and 0 < v[0] <= v[1]):
            raise ValueError(f"{v}: two heights in metres, lowest first, e.g. [1.2, 1.8]")
        return v

    @field_validator("tape_photos")
    @classmethod
    def _tape(cls, v: list[int]) -> list[int]:
        if v[0] == v[1] or min(v) < 0:
            raise ValueError(f"{v}: two different photo indices of the walk, e.g. [0, 5]")
        return v
