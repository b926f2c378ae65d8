"""Settings of the guide (``guide:`` in config.yaml): the page of the next shots and the
server that takes a person's photos back."""

from __future__ import annotations

from pydantic import Field

from scenebot.settings import Settings


class GuideConfig(Settings):
    """The guide page (``round_XXX/guide/index.html``) and ``scenebot guide serve``."""

    photo_width: int = Field(
        320,
        ge=32,
        le=2000,
        description="Width (pixels) of the photo already taken shown beside each shot (where "
        "to stand from), copied into the page.",
    )
    host: str = Field(
        "127.0.0.1",
        min_length=1,
        description="guide serve: the address to listen on. 127.0.0.1: this computer only; "
        "0.0.0.0: every network interface (a phone on the same network; anyone on that "
        "network can then upload photos).",
    )
    port: int = Field(8765, ge=0, le=65535, description="guide serve: the port (0: any free).")
    max_upload_mb: float = Field(
        40.0,
        gt=0,
        description="guide serve: photos larger than this (MB, 10^6 bytes) are refused "
        "(a phone's JPEG is 2-12 MB; a PNG screenshot can be more).",
    )
    max_request_photos: int = Field(
        100,
        ge=1,
        description="guide serve: most photos in one upload (the request is refused above "
        "max_request_photos x max_upload_mb).",
    )
    fulfil_distance_m: float = Field(
        0.3,
        gt=0,
        description="robot: guided, person-sim: a registered photo fulfils a shot of the "
        "previous round's guide when its camera centre lies within this of the shot's "
        "(map units: metres with a metric scale) ...",
    )
    fulfil_heading_deg: float = Field(
        20.0, gt=0, le=180, description="... its heading within this of the shot's (degrees) ..."
    )
    fulfil_pitch_deg: float = Field(
        15.0, gt=0, le=180, description="... and its tilt within this of the shot's (degrees)."
    )
