"""Pydantic model of the optional ``motion:`` section: limits of jerk-limited moves and of
taught-path replay (``hofto-hw mode move|replay``), and the recording buffer of
``mode drag --record``. Loading and checking only."""

from __future__ import annotations

from pydantic import Field

from hofto_hw.config.base import FileModel, PositiveFloat


class MotionConfig(FileModel):
    """Scales of the robot's joint limits for moves and replay, and the jerk limit."""

    velocity_scale: float = Field(0.5, gt=0.0, le=1.0, description="of the velocity limits")
    acceleration_scale: float = Field(0.5, gt=0.0, le=1.0, description="of the acceleration limits")
    default_acceleration: PositiveFloat = Field(
        5.0, description="[rad/s²] for joints whose acceleration limit is not given"
    )
    jerk: list[PositiveFloat] | None = Field(
        None, description="[rad/s³] per joint; None = 10 x the scaled acceleration limit"
    )
    record_seconds: PositiveFloat = Field(
        300.0,
        le=3600.0,
        description="[s] longest taught path `mode drag --record` keeps (allocated per request: "
        "(n + 1) x 8 bytes per tick, 16.8 MB for 300 s of six joints at 1 kHz)",
    )

    def limits(self, model: object) -> tuple[list[float], list[float], list[float]]:
        """(velocity, acceleration, jerk) per joint for a RobotModel."""
        lim = model.limits  # type: ignore[attr-defined]
        n = len(lim.velocity)
        vel = [
            (v if v != float("inf") else 1.0) * self.velocity_scale for v in lim.velocity.tolist()
        ]
        acc = [
            (a if a != float("inf") else self.default_acceleration) * self.acceleration_scale
            for a in lim.acceleration.tolist()
        ]
        jerk = list(self.jerk) if self.jerk is not None else [10.0 * a for a in acc]
        if len(jerk) != n:
            raise ValueError(f"motion.jerk has {len(jerk)} entries, expected {n}")
        return vel, acc, jerk
