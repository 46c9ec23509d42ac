"""Runtime safety profiles (``safety.profiles``): named sets a client may switch between
while the service runs (``Robot.set_safety_profile``), each checked at load time against
bounds the same file sets.

    safety:
      profiles:
        active: normal               # the profile the run starts with
        bounds: {collision_scale_max: 1.5, speed_scale_max: 1.0, drag_speed_scale_max: 1.0,
                 drag_mass_scale_min: 0.5, drag_damping_scale_min: 0.5}
        sets:
          normal: {collision_scale: 1.0, speed_scale: 1.0}
          reduced: {collision_scale: 0.8, speed_scale: 0.25, drag_speed_scale: 0.5}
          contact-task: {collision_scale: 1.4, speed_scale: 0.1, drag_mass_scale: 2.0,
                         drag_damping_scale: 2.0, drag_speed_scale: 0.4}

``collision_scale``: factor on every collision and contact threshold of
``safety.collision`` (all terms: base, velocity, acceleration, reversal, standstill), at most
``bounds.collision_scale_max``; ``speed_scale``: fraction of the ``motion:`` velocity and
acceleration limits of moves and replays, at most ``bounds.speed_scale_max`` (itself at most
1: no profile moves faster than the robot's limits allow). The drag (hand guiding) factors:
``drag_mass_scale`` and ``drag_damping_scale`` on the admittance's virtual mass M_a and
damping B_a (translation, rotation and joint space alike), at least
``bounds.drag_mass_scale_min`` / ``bounds.drag_damping_scale_min`` (a profile cannot make the
arm lighter or less damped under the hand than the bounds allow) and at most 10, and
``drag_speed_scale`` on every speed limit of the ``drag:`` section (tool, rotation, joints),
at most ``bounds.drag_speed_scale_max`` (itself at most 1: never faster than the drag
section, which ISO 10218-1 caps); each profile's M_a, B_a must keep the admittance stable at
the loop rate (``drag.check_rate``, checked at load). A switch happens only at standstill
(the loop refuses it while the arm moves or the enabling input is pressed) and is a
flight-log event.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field, model_validator

from hofto_hw.config.base import FileModel
from hofto_hw.config.drag import DragConfig

Scale = Annotated[float, Field(gt=0.0, allow_inf_nan=False)]


class ProfileBounds(FileModel):
    """The largest values a profile may set."""

    collision_scale_max: Scale = Field(1.0, le=10.0)
    speed_scale_max: Scale = Field(1.0, le=1.0)
    drag_speed_scale_max: Scale = Field(1.0, le=1.0)
    drag_mass_scale_min: Scale = Field(1.0, le=10.0)
    drag_damping_scale_min: Scale = Field(1.0, le=10.0)


class SafetyProfile(FileModel):
    """One named set (see the module docstring)."""

    collision_scale: Scale = 1.0
    speed_scale: Annotated[float, Field(gt=0.0, le=1.0, allow_inf_nan=False)] = 1.0
    drag_mass_scale: Annotated[float, Field(gt=0.0, le=10.0, allow_inf_nan=False)] = 1.0
    drag_damping_scale: Annotated[float, Field(gt=0.0, le=10.0, allow_inf_nan=False)] = 1.0
    drag_speed_scale: Annotated[float, Field(gt=0.0, le=1.0, allow_inf_nan=False)] = 1.0

    def drag_factors(self) -> tuple[float, float, float]:
        """(mass, damping, speed) factors of the drag section's admittance."""
        return (self.drag_mass_scale, self.drag_damping_scale, self.drag_speed_scale)


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
            if p.drag_speed_scale > b.drag_speed_scale_max:
                raise ValueError(
                    f"sets.{name}.drag_speed_scale: {p.drag_speed_scale} is above "
                    f"bounds.drag_speed_scale_max = {b.drag_speed_scale_max}"
                )
            for key, low in (
                ("drag_mass_scale", b.drag_mass_scale_min),
                ("drag_damping_scale", b.drag_damping_scale_min),
            ):
                if getattr(p, key) < low:
                    raise ValueError(
                        f"sets.{name}.{key}: {getattr(p, key)} is below bounds.{key}_min = {low}"
                    )
        if self.active not in self.sets:
            raise ValueError(f"active: {self.active!r} is not one of sets ({', '.join(self.sets)})")
        return self

    def check_drag(self, drag: DragConfig, rate_hz: float, n: int) -> None:
        """ValueError naming the profile whose drag factors make ``drag``'s admittance
        unstable or ringing at ``rate_hz`` (DragConfig.check_rate on the scaled values)."""
        for name, p in self.sets.items():
            if p.drag_factors() == (1.0, 1.0, 1.0):
                continue
            try:
                scaled_drag(drag, p).check_rate(rate_hz, n)
            except ValueError as exc:
                raise ValueError(f"sets.{name} (drag factors): {exc}") from None

    def names(self) -> list[str]:
        """Profile names in a fixed order (the index the flight log records)."""
        return sorted(self.sets)


def scaled_drag(drag: DragConfig, profile: SafetyProfile) -> DragConfig:
    """``drag`` with ``profile``'s factors on M_a and B_a (for the load-time checks; the loop
    scales its admittance's arrays in place, hofto_hw.control.drag.DragController.apply_profile)."""
    m, b, _ = profile.drag_factors()
    upd: dict = {
        "mass": drag.mass * m,
        "damping": drag.damping * b,
        "rotational_mass": drag.rotational_mass * m,
        "rotational_damping": drag.rotational_damping * b,
    }
    if drag.joint_mass is not None:
        upd["joint_mass"] = [v * m for v in drag.joint_mass]
    if drag.joint_damping is not None:
        upd["joint_damping"] = [v * b for v in drag.joint_damping]
    return drag.model_copy(update=upd)
