"""Pydantic models of the ``safety:`` section: stop categories, limits, bus health, collision.

Every fault class has exactly one stop category in the sense of IEC 60204-1:

- 0: remove power now (drives: Disable voltage; the holding brakes close);
- 1: controlled stop with power (drives: quick-stop ramp 0x6085), then remove power;
- 2: controlled stop, power stays on (the controller ramps to standstill and holds).

Units SI at the joint side. All floats are finite (``allow_inf_nan=False``). Loading and
checking only: nothing here runs in the tick.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from hofto_hw.config.base import FileModel
from hofto_hw.config.collision import ThresholdTerms
from hofto_hw.config.payload import PayloadConfig
from hofto_hw.config.profiles import ProfilesConfig

Finite = Annotated[float, Field(allow_inf_nan=False)]
NonNeg = Annotated[float, Field(ge=0.0, allow_inf_nan=False)]
Positive = Annotated[float, Field(gt=0.0, allow_inf_nan=False)]
Category = Literal[0, 1, 2]


class StopCategories(FileModel):
    """The stop category of each fault class (``log_failure: null`` = report only)."""

    collision: Category = 1
    position_limit: Category = 1
    velocity_limit: Category = 1
    torque_limit: Category = 1
    following_error: Category = 1
    position_jump: Category = 0
    non_finite: Category = 0
    bus_loss: Category = 0
    drive_fault: Category = 0
    drive_disabled: Category = 0
    overrun: Category = 1
    stop_request: Category = 1
    log_failure: Category | None = None
    enabling_released: Category = 2  # ISO 10218-1 hand guiding: a release holds
    sto: Category = 0  # safe torque off: the power is already gone
    brake: Category = 1  # a brake fault or a brake that did not release: stop, then close


class LimitsSafetyConfig(FileModel):
    """Joint supervision on measured values (limits themselves come from the robot model).

    ``position_margin`` [rad] shrinks the model's position range (soft limits);
    ``velocity_scale`` / ``torque_scale`` scale the model's velocity / torque limits;
    ``following_error`` [rad] bounds |q_cmd - q| per joint while the drives track the
    command, judged on fresh samples only (a stale sample is an old q against a newer q_cmd;
    a run of them is the bus loss); ``position_jump`` [rad] bounds |q_k - q_{k-1}| between
    two fresh samples (an encoder glitch, not motion).
    """

    position_margin: NonNeg = 0.02
    velocity_scale: Positive = 1.0
    torque_scale: Positive = 1.0
    velocity: list[Positive] | None = Field(None, description="override per joint [rad/s]")
    torque: list[Positive] | None = Field(None, description="override per joint [N·m]")
    following_error: Positive = 0.05
    position_jump: Positive = 0.02


class BusHealthConfig(FileModel):
    """Bus supervision: ``lost_cycles`` consecutive exchanges that are not ok or not fresh
    (lost frames, working-counter errors, missing TPDOs, stale data) make a bus-loss fault."""

    lost_cycles: Annotated[int, Field(ge=1, le=1000)] = 3


class ThresholdSet(FileModel):
    """Per-joint thresholds [N·m] for the nominal and the acceleration phase."""

    nominal: list[Positive]
    acceleration: list[Positive]

    @model_validator(mode="after")
    def _lengths(self) -> ThresholdSet:
        if len(self.nominal) != len(self.acceleration):
            raise ValueError(
                f"acceleration has {len(self.acceleration)} entries, nominal has "
                f"{len(self.nominal)} (one per joint)"
            )
        return self


class CollisionLevelsConfig(ThresholdTerms):
    """Two-level collision detection on the estimated external torque (see
    safety/collision/__init__.py, the one monitor replay and the loop share).

    ``contact``: reported, clears itself; ``collision``: a stop (latched by the stop
    controller). Each level's effective threshold is its phase's value plus the terms of
    :class:`~hofto_hw.config.collision.ThresholdTerms` (``velocity_gain``·|qd| and, when
    given, acceleration, reversal and standstill terms; shared by both levels); the
    acceleration phase holds while any joint's reference acceleration exceeds
    ``acceleration_phase`` [rad/s²] and ``phase_hold`` [s] after.
    ``observer``: which estimate decides; ``both`` combines hofto and momentum with
    ``logic`` (any: the first to cross; all: both must cross; mean: the mean of their
    ratios |tau_ext|/threshold must cross).
    ``tool_force`` [N]: optional limit on the tool force |F| of the damped
    F = (Jᵀ)⁺·tau_ext of the first deciding observer (off by default).
    ``settle_time`` [s]: the monitor does not judge for this long after the observers are
    (re)started and after the drives are (re)enabled: the estimate first converges and the
    arm settles into its position loop (a fast observer reads that settling as a contact).
    """

    observer: Literal["hofto", "momentum", "both"] = "hofto"
    logic: Literal["any", "all", "mean"] = "any"
    contact: ThresholdSet
    collision: ThresholdSet
    acceleration_phase: Positive = 2.0
    phase_hold: NonNeg = 0.1
    debounce_time: NonNeg = 0.0
    release_time: NonNeg = 0.05
    tool_force: Positive | None = None
    settle_time: NonNeg = 0.0

    def joints(self) -> int:
        return len(self.collision.nominal)

    @model_validator(mode="after")
    def _check(self) -> CollisionLevelsConfig:
        n = len(self.collision.nominal)
        if len(self.contact.nominal) != n:
            raise ValueError(f"contact has {len(self.contact.nominal)} joints, collision has {n}")
        self._check_terms("collision.nominal")
        for phase in ("nominal", "acceleration"):
            lo, hi = getattr(self.contact, phase), getattr(self.collision, phase)
            bad = [j for j in range(n) if lo[j] > hi[j]]
            if bad:
                raise ValueError(
                    f"contact.{phase}[{bad[0]}] = {lo[bad[0]]} is above collision.{phase}"
                    f"[{bad[0]}] = {hi[bad[0]]} (contact must be the lower level)"
                )
        return self


class SafetyConfig(FileModel):
    """The ``safety:`` section."""

    categories: StopCategories = Field(default_factory=StopCategories)
    limits: LimitsSafetyConfig = Field(default_factory=LimitsSafetyConfig)
    bus: BusHealthConfig = Field(default_factory=BusHealthConfig)
    collision: CollisionLevelsConfig | None = None
    payload: PayloadConfig = Field(default_factory=PayloadConfig)
    profiles: ProfilesConfig | None = None  # runtime safety profiles (config/profiles.py)
    overrun_streak: Annotated[int, Field(ge=1, le=100000)] = Field(
        20, description="consecutive missed deadlines that make a fault (Franka: 20)"
    )
