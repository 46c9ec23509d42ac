"""Runtime safety profiles (``safety.profiles``): named sets a client may switch between
while the service runs (``Robot.set_safety_profile``), each checked at load time against
bounds the same file sets.

    safety:
      profiles:
        active: normal               # the profile the run starts with
        bounds: {collision_scale_max: 1.5, speed_scale_max: 1.0}
        sets:
          normal: {collision_scale: 1.0, speed_scale: 1.0}
          reduced: {collision_scale: 0.8, speed_scale: 0.25}
          contact-task: {collision_scale: 1.4, speed_scale: 0.1}

``collision_scale``: factor on every collision and contact threshold of
``safety.collision`` (all terms: base, velocity, acceleration, reversal, standstill), at most
``bounds.collision_scale_max``; ``speed_scale``: fraction of the ``motion:`` velocity and
acceleration limits of moves and replays, at most ``bounds.speed_scale_max`` (itself at most
1: no profile moves faster than the robot's limits allow). A switch happens only at
standstill (the loop refuses it while the arm moves) and is a flight-log event.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field, model_validator

from hofto_hw.config.base import FileModel

Scale = Annotated[float, Field(gt=0.0, allow_inf_nan=False)]


class ProfileBounds(FileModel):
    """The largest values a profile may set."""

    collision_scale_max: Scale = Field(1.0, le=10.0)
    speed_scale_max: Scale = Field(1.0, le=1.0)


class SafetyProfile(FileModel):
    """One named set (see the module docstring)."""

    collision_scale: Scale = 1.0
    speed_scale: Annotated[float, Field(gt=0.0, le=1.0, allow_inf_nan=False)] = 1.0


class ProfilesConfig(FileModel):
    """``safety.profiles``: ``sets`` by name, the ``active`` one at start, the ``bounds``."""

    active: str
    bounds: ProfileBounds = Field(default_factory=ProfileBounds)
    sets: dict[str, SafetyProfile]

    @model_validator(mode="after")
    def _checked(self) -> ProfilesConfig:
        if not self.sets:
            raise ValueError("sets: at least one profile")
        for name, p in self.sets.items():
            if not name or len(name) > 40 or not name.replace("-", "").replace("_", "").isalnum():
                raise ValueError(f"sets: profile name {name!r}: letters, digits, - and _ only")
            b = self.bounds
            if p.collision_scale > b.collision_scale_max:
                raise ValueError(
                    f"sets.{name}.collision_scale: {p.collision_scale} is above "
                    f"bounds.collision_scale_max = {b.collision_scale_max}"
                )
            if p.speed_scale > b.speed_scale_max:
                raise ValueError(
                    f"sets.{name}.speed_scale: {p.speed_scale} is above "
                    f"bounds.speed_scale_max = {b.speed_scale_max}"
                )
        if self.active not in self.sets:
            raise ValueError(f"active: {self.active!r} is not one of sets ({', '.join(self.sets)})")
        return self

    def names(self) -> list[str]:
        """Profile names in a fixed order (the index the flight log records)."""
        return sorted(self.sets)
