"""Pydantic models of the collision monitor's settings (safety/collision/): the threshold
terms shared by both forms, ``monitor:`` in a thresholds file (:class:`CollisionConfig`, one
level) and ``safety.collision`` of a system config (CollisionLevelsConfig in
hofto_hw/config/safety.py, contact and collision levels). Units SI at the joint side; lists
are per joint.

Effective threshold of joint j at tick k (see safety/collision/__init__.py):

    thr_j = base_j + velocity_gain_j·|qd_j| + acceleration_gain_j·|a_j| + reversal_margin_j·r_j
            + standstill_margin_j·s_j

with a_j the low-passed acceleration [rad/s²], r_j in [0, 1] the velocity-reversal
indicator (1 while a joint that was moving passes through |qd| < reversal_velocity) and s_j
= exp(-(qd_j/standstill_velocity)²) the standstill indicator (1 at rest however long, ~0 in
motion): held friction at rest then no longer forces the base, i.e. the threshold in motion,
up. Without ``standstill_margin`` the threshold is today's.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field, model_validator

from hofto_hw.config.base import FileModel, NonNegFloat, PositiveFloat

#: the per-joint lists of :class:`ThresholdTerms` (None = 0 on every joint)
TERM_LISTS = ("velocity_gain", "acceleration_gain", "reversal_margin", "standstill_margin")


class ThresholdTerms(FileModel):
    """The motion-dependent terms of a threshold and the filters of their features."""

    velocity_gain: list[NonNegFloat] | None = Field(None, description="[N·m·s/rad] per joint")
    acceleration_gain: list[NonNegFloat] | None = Field(None, description="[N·m·s²/rad] per joint")
    reversal_margin: list[NonNegFloat] | None = Field(
        None, description="extra threshold during a velocity reversal [N·m] per joint"
    )
    standstill_margin: list[NonNegFloat] | None = Field(
        None, description="extra threshold at standstill [N·m] per joint (held friction)"
    )
    standstill_velocity: PositiveFloat = Field(
        0.02, description="width of the standstill indicator exp(-(qd/v)²) [rad/s]"
    )
    standstill_time: NonNegFloat = Field(
        0.0,
        description="the standstill indicator rises with this time constant after a stop [s] "
        "(0 = at once); it drops at once when the joint moves",
    )
    reversal_velocity: PositiveFloat = Field(
        0.05, description="|qd| below which a moving joint counts as reversing [rad/s]"
    )
    moving_time: PositiveFloat = Field(
        0.5, description="how long a joint counts as moving after |qd| fell [s]"
    )
    reversal_time: PositiveFloat = Field(0.2, description="decay of the reversal indicator [s]")
    accel_filter_hz: PositiveFloat = Field(5.0, description="low-pass on the acceleration [Hz]")
    release_ratio: Annotated[float, Field(gt=0.0, le=1.0)] = Field(
        0.8, description="hysteresis: a tripped joint releases below ratio·threshold"
    )

    def joints(self) -> int:
        """Number of joints (the length of the base thresholds)."""
        raise NotImplementedError

    def _check_terms(self, against: str) -> None:
        """Every per-joint list has as many entries as ``against`` (the field giving n)."""
        n = self.joints()
        for name in TERM_LISTS:
            v = getattr(self, name)
            if v is not None and len(v) != n:
                raise ValueError(f"{name} has {len(v)} entries, {against} has {n} (one per joint)")


class CollisionConfig(ThresholdTerms):
    """Thresholds on the estimated external torque and the tools that make them robust."""

    base: list[PositiveFloat] = Field(description="threshold at rest per joint [N·m]")
    debounce_time: NonNegFloat = Field(
        0.02, description="a joint must stay above its threshold this long to trip [s]"
    )
    release_time: NonNegFloat = Field(0.1, description="... for at least this long [s]")

    def joints(self) -> int:
        return len(self.base)

    @model_validator(mode="after")
    def _lengths(self) -> CollisionConfig:
        self._check_terms("base")
        return self
