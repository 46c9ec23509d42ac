"""Pydantic models of the YAML configuration (``configs/*.yaml``).

Units are SI at the joint side everywhere: rad, rad/s, N·m, kg·m². Per-joint lists have one
entry per joint in ``robot.joints`` order. Models forbid unknown keys so that a typo fails
loudly instead of silently falling back to a default, and refuse non-finite numbers (see
:mod:`hofto_hw.config.base`).

These models are for loading and checking files only; nothing here runs inside the tick.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field, field_validator, model_validator

from hofto_hw.config.base import FileModel, NonNegFloat, PositiveFloat
from hofto_hw.config.collision import CollisionConfig
from hofto_hw.config.drag import DragConfig
from hofto_hw.config.drives import BusConfig
from hofto_hw.config.motion import MotionConfig
from hofto_hw.config.payload import PayloadConfig, RatedPayload
from hofto_hw.config.runtime import RunConfig, ServiceConfig
from hofto_hw.config.safety import SafetyConfig

# --------------------------------------------------------------------------------- robot


class FrictionConfig(FileModel):
    """Joint friction per eq. (12): ``f = Fc·sign(qd) + Fv·qd + B`` (+ optional Stribeck).

    ``smooth_velocity`` [rad/s] replaces sign(qd) by tanh(qd / smooth_velocity); 0 keeps the
    hard sign. Stribeck adds ``(Fs - Fc)·exp(-(qd/vs)²)·sign(qd)`` (used by the plant; the
    identified model normally has Fs = Fc, i.e. no Stribeck term).
    """

    coulomb: list[NonNegFloat] = Field(description="Coulomb friction Fc per joint [N·m]")
    viscous: list[NonNegFloat] = Field(description="viscous friction Fv per joint [N·m·s/rad]")
    bias: list[float] | None = Field(None, description="constant offset B per joint [N·m]")
    stribeck_static: list[NonNegFloat] | None = Field(
        None, description="static (breakaway) friction Fs per joint [N·m], >= Fc"
    )
    stribeck_velocity: list[PositiveFloat] | None = Field(
        None, description="Stribeck velocity vs per joint [rad/s]"
    )
    smooth_velocity: NonNegFloat = Field(
        0.0, description="tanh smoothing velocity for sign(qd) [rad/s]; 0 = hard sign"
    )
    held: list[NonNegFloat] | None = Field(
        None,
        description="held friction Fh per joint [N·m]: Fh·h·exp(-(qd/v_h)²), h = sign of the "
        "last velocity outside the band v_h (friction with memory at rest)",
    )
    held_velocity: PositiveFloat = Field(
        0.005, description="velocity band v_h of the held friction [rad/s]"
    )
    quadratic: list[float] | None = Field(
        None, description="quadratic friction Fq per joint: Fq·qd·|qd| [N·m·s²/rad²]"
    )


class LimitsConfig(FileModel):
    """Joint limits; any field left out is taken from the URDF."""

    position_lower: list[float] | None = None
    position_upper: list[float] | None = None
    velocity: list[PositiveFloat] | None = None
    acceleration: list[PositiveFloat] | None = None
    torque: list[PositiveFloat] | None = None


class RobotConfig(FileModel):
    """One arm: kinematics and nominal dynamics from a URDF, plus drive-side data."""

    name: str
    urdf: Path = Field(description="URDF file, relative to the config file")
    joints: list[str] = Field(min_length=1, description="actuated joints in drive order")
    tool_frame: str = Field(description="URDF frame of the tool centre point")
    base_frame: str | None = Field(None, description="frame Cartesian quantities are given in")
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    rotor_inertia: list[NonNegFloat] | None = Field(
        None, description="reflected rotor inertia per joint (joint side) [kg·m²]"
    )
    friction: FrictionConfig | None = None
    limits: LimitsConfig = Field(default_factory=LimitsConfig)
    home: list[float] | None = Field(None, description="home configuration [rad]")
    payload: PayloadConfig | None = Field(
        None, description="tool or load on the tool frame (hofto-hw payload identify)"
    )
    rated_payload: RatedPayload | None = Field(
        None, description="the load the arm is rated for (bounds of Robot.set_payload)"
    )
    parameters: Path | None = Field(
        None, description="identified-parameters file (hofto-hw identify); overrides URDF"
    )

    @model_validator(mode="after")
    def _per_joint_lengths(self) -> RobotConfig:
        n = len(self.joints)
        if len(set(self.joints)) != n:
            raise ValueError("joints must be unique")
        checks: list[tuple[str, list[float] | None]] = [
            ("rotor_inertia", self.rotor_inertia),
            ("home", self.home),
        ]
        if self.friction is not None:
            f = self.friction
            checks += [
                ("friction.coulomb", f.coulomb),
                ("friction.viscous", f.viscous),
                ("friction.bias", f.bias),
                ("friction.stribeck_static", f.stribeck_static),
                ("friction.stribeck_velocity", f.stribeck_velocity),
            ]
        lim = self.limits
        checks += [
            ("limits.position_lower", lim.position_lower),
            ("limits.position_upper", lim.position_upper),
            ("limits.velocity", lim.velocity),
            ("limits.acceleration", lim.acceleration),
            ("limits.torque", lim.torque),
        ]
        _check_lengths(checks, n)
        return self


def _check_lengths(checks: list[tuple[str, list | None]], n: int) -> None:
    for name, values in checks:
        if values is not None and len(values) != n:
            raise ValueError(f"{name} has {len(values)} entries, expected {n} (one per joint)")


# ------------------------------------------------------------------------------ observers


class _ObserverConfig(FileModel):
    """What every observer config tells the system config: its per-joint lists."""

    def per_joint_fields(self) -> list[tuple[str, list | None]]:
        """(field, values) of every per-joint list, for the length check of SystemConfig."""
        return []


class _EulerObserverConfig(_ObserverConfig):
    """An observer integrated by explicit Euler in ``substeps`` steps per tick."""

    substeps: int = Field(1, ge=1, le=100, description="explicit-Euler substeps per tick")


class DirectConfig(_ObserverConfig):
    """Direct estimation, eq. (2), acceleration by differentiating measured velocity."""

    type: Literal["direct"] = "direct"
    accel_filter_hz: PositiveFloat | None = Field(
        None, description="first-order low-pass on the differentiated velocity; None = raw"
    )


class EsoConfig(_EulerObserverConfig):
    """Linear ESO, eq. (5): diagonal gains k1 [1/s], k2 [1/s²], k3 [1/s³] per joint."""

    type: Literal["eso"] = "eso"
    k1: list[PositiveFloat]
    k2: list[PositiveFloat]
    k3: list[PositiveFloat]

    def per_joint_fields(self) -> list[tuple[str, list | None]]:
        """(field, values) of every per-joint list, for the length check of SystemConfig."""
        return [("k1", self.k1), ("k2", self.k2), ("k3", self.k3)]


class DobConfig(_ObserverConfig):
    """Disturbance observer with nominal inertia and a first-order low-pass (see dob.py)."""

    type: Literal["dob"] = "dob"
    cutoff: list[PositiveFloat] = Field(description="low-pass cutoff g per joint [rad/s]")
    nominal_inertia: list[PositiveFloat] | None = Field(
        None, description="Jn per joint [kg·m²]; None = diag M(home)"
    )

    def per_joint_fields(self) -> list[tuple[str, list | None]]:
        """(field, values) of every per-joint list, for the length check of SystemConfig."""
        return [("cutoff", self.cutoff), ("nominal_inertia", self.nominal_inertia)]


class MomentumConfig(_ObserverConfig):
    """Generalized-momentum observer (De Luca), first order, gain K_O per joint [1/s]."""

    type: Literal["momentum"] = "momentum"
    gain: list[PositiveFloat]

    def per_joint_fields(self) -> list[tuple[str, list | None]]:
        """(field, values) of every per-joint list, for the length check of SystemConfig."""
        return [("gain", self.gain)]


class StaConfig(_EulerObserverConfig):
    """Super-twisting observer (Remark 7): gains of the 1/2, 1/2 and sign stages."""

    type: Literal["sta"] = "sta"
    l1: list[PositiveFloat]
    l2: list[PositiveFloat]
    l3: list[PositiveFloat]

    def per_joint_fields(self) -> list[tuple[str, list | None]]:
        """(field, values) of every per-joint list, for the length check of SystemConfig."""
        return [("l1", self.l1), ("l2", self.l2), ("l3", self.l3)]


class HoftoConfig(_ObserverConfig):
    """High-order finite-time observer, eq. (17), of order n (n + 2 observer states).

    Powers: either ``sigma`` in (-1/(n+2), 0), giving stage i (i = 1..n+2) the power
    m_{i+1} = 1 + i·sigma, or ``powers`` listing the n + 2 stage powers explicitly (each in
    [0, 1]; 0 is sign(), 1 is linear: Remark 7's ESO and STA special cases).

    ``form`` says which convention ``gains`` are in:
    - ``eq17``: every stage driven by e1 = x1 - z1, gains L_i of eq. (17) as printed;
    - ``recursive``: Levant's nested form (each stage driven by the previous stage's output),
      the convention of the paper's Section IV numbers (see docs/observers.md).
    """

    type: Literal["hofto"] = "hofto"
    order: int = Field(2, ge=1, le=8, description="n: the (n-1)-th derivative of x3 is tracked")
    form: Literal["eq17", "recursive"] = "recursive"
    sigma: float | None = None
    powers: list[Annotated[float, Field(ge=0.0, le=1.0)]] | None = None
    gains: list[list[PositiveFloat]] = Field(description="n + 2 rows of per-joint gains L_i")
    substeps: int = Field(1, ge=1, le=100, description="integration substeps per tick")
    discretisation: Literal["taylor", "euler"] = Field(
        "taylor", description="taylor: exact on polynomial signals; euler: plain forward Euler"
    )

    @model_validator(mode="after")
    def _check(self) -> HoftoConfig:
        n = self.order
        if (self.sigma is None) == (self.powers is None):
            raise ValueError("give exactly one of sigma or powers")
        if self.sigma is not None and not (-1.0 / (n + 2) < self.sigma < 0.0):
            raise ValueError(
                f"sigma = {self.sigma} is outside (-1/(n+2), 0) = ({-1.0 / (n + 2):.4f}, 0) "
                f"for order n = {n}"
            )
        if self.powers is not None and len(self.powers) != n + 2:
            raise ValueError(f"powers has {len(self.powers)} entries, expected n + 2 = {n + 2}")
        if len(self.gains) != n + 2:
            raise ValueError(f"gains has {len(self.gains)} rows, expected n + 2 = {n + 2}")
        return self

    def per_joint_fields(self) -> list[tuple[str, list | None]]:
        """(field, values) of every per-joint list, for the length check of SystemConfig."""
        return [(f"gains[{i}]", g) for i, g in enumerate(self.gains)]

    def stage_powers(self) -> list[float]:
        """The n + 2 powers m_2 .. m_{n+3} applied to the stage errors."""
        if self.powers is not None:
            return list(self.powers)
        assert self.sigma is not None
        return [1.0 + i * self.sigma for i in range(1, self.order + 3)]


# The observer types: this union (config side) and hofto_hw.observers.registry.OBSERVERS (builders,
# replay defaults) list the same classes; a test keeps them in step.
ObserverConfig = Annotated[
    DirectConfig | EsoConfig | DobConfig | MomentumConfig | StaConfig | HoftoConfig,
    Field(discriminator="type"),
]


# ----------------------------------------------------------------------------- simulation


class ExternalTorqueConfig(FileModel):
    """One external-torque component applied by the simulated world.

    ``kind``:
    - ``constant``: amplitude per joint [N·m];
    - ``ramp``: amplitude + slope·(t - start) [N·m, N·m/s];
    - ``parabola``: amplitude + slope·τ + curvature·τ², τ = t - start;
    - ``sine``: amplitude·sin(2π·frequency·τ + phase), τ = t - start (phase 0 starts smoothly);
    - ``chirp``: amplitude·sin(phase(t)), frequency sweeping linearly from ``frequency`` to
      ``frequency_end`` over ``duration``;
    - ``contact``: stiff spring-damper wall on the Cartesian position of ``frame`` (see
      drivers/sim/scenarios.py);
    - ``push``: Cartesian force at the tool (``force`` [N]) mapped to joints by J^T, with a
      smooth raised-cosine profile over ``duration``, or with ``ramp`` [s] set, linear ramps
      of that length at both ends and the full force in between (a hand holding a push).
    Each component is active on [start, start + duration) (duration None = forever).
    """

    kind: Literal["constant", "ramp", "parabola", "sine", "chirp", "contact", "push"]
    start: NonNegFloat = 0.0
    duration: PositiveFloat | None = None
    amplitude: list[float] | None = None
    slope: list[float] | None = None
    curvature: list[float] | None = None
    frequency: list[NonNegFloat] | None = None
    frequency_end: list[NonNegFloat] | None = None
    phase: list[float] | None = None
    frame: str | None = None
    force: tuple[float, float, float] | None = None
    wall_point: tuple[float, float, float] | None = None
    wall_normal: tuple[float, float, float] | None = None
    stiffness: PositiveFloat | None = Field(None, description="contact stiffness [N/m]")
    damping: NonNegFloat | None = Field(None, description="contact damping [N·s/m]")
    ramp: PositiveFloat | None = Field(None, description="push: linear ramp time [s]")


class SimulationConfig(FileModel):
    """The simulated arm (``drivers.sim.Plant``): how the "true" arm differs from the model."""

    seed: int = 0
    substeps: int = Field(4, ge=1, le=100, description="integration substeps per tick")
    model_error: NonNegFloat = Field(
        0.0, description="relative random error of the true link inertial parameters"
    )
    friction: FrictionConfig | None = Field(
        None, description="true friction; None = the robot's friction"
    )
    encoder_counts_per_rev: list[PositiveFloat] | None = Field(
        None, description="joint-side encoder resolution for quantisation; None = exact"
    )
    torque_noise: NonNegFloat = Field(0.0, description="std of measured torque noise [N·m]")
    velocity_noise: NonNegFloat = Field(0.0, description="std of measured velocity noise [rad/s]")
    external: list[ExternalTorqueConfig] = Field(default_factory=list)


#: highest loop.rate_hz [Hz] (by design: the tick takes tens of µs; EtherCAT and CAN cycles
#: faster than 100 µs are out of reach of a Python loop)
MAX_RATE_HZ = 10_000.0
#: most samples one `mode drag --record` request allocates: an hour at 1 kHz
MAX_RECORD_SAMPLES = 3_600_000


class LoopConfig(FileModel):
    """The real-time loop; the drive bus cycles at the same rate."""

    rate_hz: float = Field(
        1000.0,
        ge=10.0,
        le=MAX_RATE_HZ,
        description="loop and bus cycle rate [Hz]; the cycle time is 1 / rate_hz (at most "
        "10 kHz: a 100 µs cycle is the shortest the Python tick can meet)",
    )
    realtime: Literal["required", "preferred", "off"] = Field(
        "preferred",
        description="SCHED_FIFO + mlockall: required refuses to start without them, "
        "preferred warns once, off does not try",
    )
    acceleration: Literal["required", "preferred"] = Field(
        "preferred",
        description="the compiled tick (numba kernels and the native dynamics shipped in the "
        "wheel; the tick has no other path, so either refuses to start without it, naming "
        "why in one line): preferred accepts NUMBA_DISABLE_JIT (the same source as Python), "
        "required (a service) refuses that too",
    )
    priority: int = Field(50, ge=1, le=99, description="SCHED_FIFO priority")
    cpus: list[int] | str | None = Field(
        None,
        description="CPU affinity of the loop: a list of CPUs, 'last' (the highest-numbered "
        "CPU the service may use, when it may use two or more: the control plane, its "
        "planner and the flight recorder's writer then run on the others; on one CPU the "
        "affinity is left as is and the run says so), or None = leave as is",
    )
    cpu_latency_us: int | None = Field(
        0,
        ge=0,
        le=1_000_000,
        description="CPU wake-up latency limit [µs] held while the loop runs with the real "
        "clock (PM QoS, /dev/cpu_dma_latency; applies to every CPU): 0 keeps idle CPUs "
        "polling instead of sleeping, for a prompt and warm wake-up at each deadline at the "
        "cost of idle power; None = the kernel's default",
    )
    observers: dict[str, ObserverConfig] | None = Field(
        None,
        description="observers the loop runs (hofto, momentum), when they differ from the "
        "top-level observers section (e.g. gains for a faster detection); None = those "
        "(`hofto-hw run` prints which it runs); empty is refused",
    )

    @field_validator("cpus", mode="before")
    @classmethod
    def _cpus_word(cls, v: Any) -> Any:
        """One message for any bad value (not one per member of the union)."""
        if v is None or v == "last":
            return v
        if isinstance(v, list) and v and all(type(c) is int and c >= 0 for c in v):
            return v
        raise ValueError("expected a list of CPU numbers (integers >= 0), 'last' or null")

    @field_validator("observers")
    @classmethod
    def _not_empty(cls, v: dict[str, ObserverConfig] | None) -> dict | None:
        if v is not None and not v:
            raise ValueError(
                "empty: name the observers the loop runs (hofto, momentum), or delete the key "
                "to run the top-level observers section (its offline gains)"
            )
        return v


class SystemConfig(FileModel):
    """A whole setup: one robot, its loop, its observers and (optionally) its simulation."""

    robot: RobotConfig
    loop: LoopConfig = Field(default_factory=LoopConfig)
    observers: dict[str, ObserverConfig] = Field(default_factory=dict)
    simulation: SimulationConfig | None = None
    collision: CollisionConfig | None = None
    bus: BusConfig | None = None
    safety: SafetyConfig = Field(default_factory=SafetyConfig)
    run: RunConfig = Field(default_factory=RunConfig)
    service: ServiceConfig = Field(default_factory=ServiceConfig)
    drag: DragConfig | None = None
    motion: MotionConfig = Field(default_factory=MotionConfig)

    @property
    def cycle_time(self) -> float:
        """The loop period and bus cycle time [s]: ``1 / loop.rate_hz`` (the single source)."""
        return 1.0 / self.loop.rate_hz

    @field_validator("observers")
    @classmethod
    def _names(cls, v: dict[str, ObserverConfig]) -> dict[str, ObserverConfig]:
        for name in v:
            if not name or not name.replace("_", "").replace("-", "").isalnum():
                raise ValueError(f"observer name {name!r} must be alphanumeric (with _ or -)")
        return v

    @model_validator(mode="after")
    def _per_joint(self) -> SystemConfig:
        n = len(self.robot.joints)
        for name, obs in self.observers.items():
            rows = obs.per_joint_fields()
            _check_lengths([(f"observers.{name}.{k}", v) for k, v in rows], n)
        if self.bus is not None:
            _check_lengths([("bus.drives", self.bus.drives)], n)
        _check_runtime_lengths(self, n)
        _check_canopen_resync(self)
        if self.motion.jerk is not None:
            _check_lengths([("motion.jerk", self.motion.jerk)], n)
        samples = self.motion.record_seconds * self.loop.rate_hz
        if samples > MAX_RECORD_SAMPLES:
            raise ValueError(
                f"motion.record_seconds = {self.motion.record_seconds:g} s at loop.rate_hz = "
                f"{self.loop.rate_hz:g} Hz is {samples:.3g} samples per taught path; at most "
                f"{MAX_RECORD_SAMPLES} ({MAX_RECORD_SAMPLES / self.loop.rate_hz:g} s here)"
            )
        if self.drag is not None:
            try:
                self.drag.check_rate(self.loop.rate_hz, n)
            except ValueError as exc:
                raise ValueError(f"drag.{exc}") from None
            if self.safety.profiles is not None:
                try:
                    self.safety.profiles.check_drag(self.drag, self.loop.rate_hz, n)
                except ValueError as exc:
                    raise ValueError(f"safety.profiles.{exc}") from None
            if self.drag.observer not in self.observers:
                raise ValueError(
                    f"drag.observer: {self.drag.observer!r} is not in observers "
                    f"({', '.join(self.observers) or 'none configured'})"
                )
        if self.simulation is not None:
            s = self.simulation
            _check_lengths([("simulation.encoder_counts_per_rev", s.encoder_counts_per_rev)], n)
            for i, ext in enumerate(s.external):
                _check_lengths(
                    [
                        (f"simulation.external[{i}].{k}", getattr(ext, k))
                        for k in (
                            "amplitude",
                            "slope",
                            "curvature",
                            "frequency",
                            "frequency_end",
                            "phase",
                        )
                    ],
                    n,
                )
        return self


def _check_canopen_resync(cfg: SystemConfig) -> None:
    """A CANopen TPDO backlog must outlast the bus-loss streak before it is written off."""
    if cfg.bus is None or cfg.bus.transport != "canopen" or cfg.bus.canopen is None:
        return
    o = cfg.bus.canopen
    resync = o.tpdo_resync or o.heartbeat_timeout or 3.0 * o.heartbeat_time
    cycles = resync * cfg.loop.rate_hz
    lost = cfg.safety.bus.lost_cycles
    if cycles <= lost:
        raise ValueError(
            f"bus.canopen.tpdo_resync = {resync:g} s is {cycles:g} cycles at "
            f"{cfg.loop.rate_hz:g} Hz, not more than safety.bus.lost_cycles = {lost}: a TPDO "
            "stream late by whole cycles would be written off before it is a bus loss"
        )


def _check_runtime_lengths(cfg: SystemConfig, n: int) -> None:
    """Per-joint lists of the safety and run sections."""
    checks: list[tuple[str, list | None]] = []
    col = cfg.safety.collision
    if col is not None:
        checks += [
            ("safety.collision.collision.nominal", col.collision.nominal),
            ("safety.collision.contact.nominal", col.contact.nominal),
        ]
    lim = cfg.safety.limits
    checks += [("safety.limits.velocity", lim.velocity), ("safety.limits.torque", lim.torque)]
    path = cfg.run.path
    if path is not None:
        checks += [
            ("run.path.amplitude", path.amplitude),
            ("run.path.period", path.period),
            ("run.path.phase", path.phase),
        ]
    _check_lengths(checks, n)
    if cfg.run.collision is not None and cfg.run.collision.joint >= n:
        raise ValueError(f"run.collision.joint = {cfg.run.collision.joint}: the arm has {n} joints")
