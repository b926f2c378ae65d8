"""The base of every settings model (the sections of config.yaml): an unknown key is an error
(a misspelt setting must not be silently ignored), and a value assigned later is checked as one
read from the file."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict


class Settings(BaseModel):
    """A section of the config, or a part of one."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)
