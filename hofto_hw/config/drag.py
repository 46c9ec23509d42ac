"""Pydantic models of the optional ``drag:`` section: sensorless hand guiding (issue 9).

The paper's eq. (34) with K_a = 0, F_d = 0: M_a·Xdd + B_a·Xd = F_ext_hat, per Cartesian axis
(or per joint in joint space), plus the limits a hand-guided arm needs. Units SI: kg, N·s/m,
kg·m², N·m·s/rad, N, N·m, m/s, rad/s, m, rad. Loading and checking only: nothing here runs in
the tick (the controllers copy what they need into arrays).
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from hofto_hw.config.base import FileModel, NonNegFloat, PositiveFloat
from hofto_hw.config.payload import PayloadConfig

#: ISO 10218-1 hand guiding: safety-rated reduced speed, at most 250 mm/s at the tool
ISO_REDUCED_SPEED = 0.25


class UnlockConfig(FileModel):
    """Which Cartesian axes the hand may move (like Franka's guiding mode): translation
    along world x, y, z and rotation (all three rotational axes together)."""

    x: bool = True
    y: bool = True
    z: bool = True
    rotation: bool = False


class WorkspaceConfig(FileModel):
    """A box the tool origin must stay in [m], world frame; ``wall`` [m] is the slow-down
    zone inside each face (speed toward a face <= distance / wall_time)."""

    lower: tuple[float, float, float]
    upper: tuple[float, float, float]

    @model_validator(mode="after")
    def _ordered(self) -> WorkspaceConfig:
        for axis, lo, hi in zip("xyz", self.lower, self.upper, strict=True):
            if lo >= hi:
                raise ValueError(f"workspace.lower.{axis} = {lo} must be below upper = {hi}")
        return self


class EnableInputConfig(FileModel):
    """Where the enabling input comes from.

    ``digital_input``: bit ``bit`` (0-31) of the drive digital inputs 0x60FD of drive
    ``axis`` (CiA 402: bits 16-31 are manufacturer inputs); ``scripted``: a simulation script
    sets it; ``socket``: a client of the control socket holds it as a lease of ``lease``
    seconds that it renews (``enable on``); not renewed in time, it is released (category 2
    while dragging), as a hand letting go of an enabling device."""

    source: Literal["digital_input", "scripted", "socket"] = "scripted"
    axis: int = Field(0, ge=0)
    bit: int = Field(17, ge=0, le=31)  # the emulated drives use bit 16 for STO
    lease: float = Field(
        0.25,
        ge=0.02,
        le=0.25,
        description="[s] how long one renewal of the remote (socket) enabling input holds it: "
        "a client that stops renewing (crashed, hung, cut off) releases it within this time",
    )


class DragConfig(FileModel):
    """The ``drag:`` section (see the module docstring and docs/drag.md)."""

    space: Literal["cartesian", "joint"] = "cartesian"
    observer: str = Field("hofto", description="name in observers: whose estimate drives")
    mass: PositiveFloat = Field(3.0, description="M_a, translation [kg]")
    damping: PositiveFloat = Field(200.0, description="B_a, translation [N·s/m]")
    rotational_mass: PositiveFloat = Field(0.15, description="M_a, rotation [kg·m²]")
    rotational_damping: PositiveFloat = Field(10.0, description="B_a, rotation [N·m·s/rad]")
    joint_mass: list[PositiveFloat] | None = Field(
        None, description="joint-space M_a per joint [kg·m²]; None = 0.3 each"
    )
    joint_damping: list[PositiveFloat] | None = Field(
        None, description="joint-space B_a per joint [N·m·s/rad]; None = 20 each"
    )
    release_damping: float = Field(
        3.0,
        ge=1.0,
        le=20.0,
        description="B_a is multiplied by this while no push is felt (inside the deadband): "
        "a released arm stops in M_a/(k·B_a) instead of M_a/B_a",
    )
    unlock: UnlockConfig = Field(default_factory=UnlockConfig)
    force_deadband: NonNegFloat = Field(
        5.0, description="|F| below this is no push [N]; unity gain above twice it"
    )
    torque_deadband: NonNegFloat = Field(0.5, description="|M| below this is no twist [N·m]")
    joint_deadband: NonNegFloat = Field(1.0, description="joint-space deadband [N·m]")
    max_tool_speed: PositiveFloat = Field(
        ISO_REDUCED_SPEED, description="tool speed limit [m/s] (ISO 10218: <= 0.25)"
    )
    max_tool_rotation_speed: PositiveFloat = Field(1.0, description="[rad/s]")
    tool_speed_margin: float = Field(
        0.1,
        ge=0.0,
        lt=1.0,
        description="the command stays this fraction below the tool speed limits: the "
        "drives' position loop overshoots the command while it takes up its following error "
        "after a hand lets go (ER3A sim, 80 N release: +3 % HOFTO, +8 % momentum)",
    )

    @property
    def command_tool_speed(self) -> float:
        """The tool speed the admittance commands at most [m/s]."""
        return self.max_tool_speed * (1.0 - self.tool_speed_margin)

    @property
    def command_tool_rotation_speed(self) -> float:
        """The tool rotation speed the admittance commands at most [rad/s]."""
        return self.max_tool_rotation_speed * (1.0 - self.tool_speed_margin)

    max_tool_acceleration: PositiveFloat = Field(
        2.5,
        description="limit of the admittance's tool acceleration [m/s²]: a released arm "
        "decelerates at most this hard, so the estimate's inertia error (model error x "
        "acceleration) stays inside the deadband instead of pushing the arm back",
    )
    max_tool_angular_acceleration: PositiveFloat = Field(
        10.0, description="the same for rotation [rad/s²]"
    )
    joint_speed_scale: float = Field(
        0.5, gt=0.0, le=1.0, description="fraction of the model's joint velocity limits"
    )
    soft_limit_margin: NonNegFloat = Field(
        0.05, description="soft joint limits this far inside the model's limits [rad]"
    )
    wall_time: PositiveFloat = Field(
        0.1, description="virtual walls: speed toward a limit <= distance / wall_time [s]"
    )
    workspace: WorkspaceConfig | None = None
    singular_manipulability: PositiveFloat = Field(
        0.004,
        description="below this manipulability w = |det J| [m³] the drag slows down and the "
        "Jacobian inverse is damped (ER3A: 0.009 at home, 0.0008 at q5 = 0.05 rad)",
    )
    singular_min_scale: float = Field(0.1, gt=0.0, le=1.0, description="speed scale at w = 0")
    dls_damping: PositiveFloat = Field(
        0.05, description="damped least squares: lambda at w = 0 [m] (0 above the threshold)"
    )
    force_limit: PositiveFloat = Field(
        150.0, description="a push above this is a stop request (drag force limit) [N]"
    )
    isolation_threshold: PositiveFloat = Field(
        1.0,
        description="tool-force hypothesis residual that means 'not at the tool' [N·m] "
        "(ER3A, 10 % model error: ~0.2 while dragging)",
    )
    isolation_force_ratio: NonNegFloat = Field(
        0.01,
        description="the isolation threshold grows by this per N of tool force let go of "
        "(the peak of the last isolation_hold_time minus now) [N·m/N]: with model error the "
        "residual grows with the arm's deceleration after a hand lets go; a contact adds "
        "to the fitted force and leaves the threshold alone",
    )
    isolation_hold_time: NonNegFloat = Field(0.3, description="decay time of that force peak [s]")
    isolation_debounce: NonNegFloat = Field(
        0.01, description="the mismatch must persist this long to count [s]"
    )
    force_filter_hz: NonNegFloat = Field(
        5.0,
        description="first-order low-pass on the observer's estimate before the drag uses "
        "it [Hz] (0 = off): a hand pushes below a few Hz, a fast collision observer chatters "
        "and rings with the admittance well above",
    )
    isolation_filter_hz: NonNegFloat = Field(
        50.0,
        description="first-order low-pass on the estimate for the off-tool contact check "
        "[Hz] (0 = off): faster than force_filter_hz, since a contact's onset must not be "
        "smeared into the tool-force fit the isolation subtracts, yet it takes the chatter "
        "of a high-gain observer off",
    )
    release_ratio: float = Field(
        0.8,
        ge=0.0,
        lt=1.0,
        description="release detector (0 = off): when the isolation-filtered estimate falls "
        "below this fraction of the force-filtered one, the drag's force is scaled down to "
        "follow it (a letting-go hand is seen at the fast filter's speed, a push still comes "
        "in smoothly)",
    )
    release_lag_ratio: float = Field(
        0.85,
        ge=0.0,
        lt=1.0,
        description="release seen in the arm's motion (0 = off): when the measured tool "
        "speed along a command that is not accelerating falls below this fraction of it, the "
        "hand has let go (the feed-forward pulls the arm back) and the drag's force is zeroed "
        "until the estimate rises again; a slow observer's estimate falls too late (paper "
        "HOFTO: at rest 121 ms after the release without, 27 ms with); needs "
        "hand_feedforward (off without it)",
    )
    tare_on_enable: bool = Field(
        True,
        description="take the estimate at the press as zero (a force-sensor tare, as UR and "
        "Franka zero the wrench on entering hand guiding): the model's gravity error at "
        "the pose where dragging starts reads as no push",
    )
    tare_time: NonNegFloat = Field(
        1.0,
        description="the tare is the mean of the estimate since drag mode began, then its "
        "exponential mean over this time [s], up to the press (0 = the press tick's "
        "sample): at standstill the estimate wanders ~1 N over ~0.1 s (held friction), one "
        "instant of it is no zero; 0.2 s still left 0.36 N·m on joint 2 (ER3A over "
        "EtherCAT, 3 kg: 1 N sideways at the tool, 5 mm/s off-axis in a 100 mm/s drag; "
        "1 s: 0.4 mm/s)",
    )
    hand_feedforward: bool = Field(
        True,
        description="while dragging, add -tau_ext_hat (tared) to the drives' torque offset: "
        "the position loop does not fight the hand (ER3A sim: the arm rests 42 ms after a "
        "release instead of 133 ms, momentum observer)",
    )
    friction_learning: bool = Field(
        True,
        description="learn the friction model's error from contact-free motion (any mode but "
        "drag, no contact, no stop) and take it off the drag's estimate: the error switches "
        "with the direction of motion, so the tare at rest cannot remove it (README main job, "
        "3 kg: 1.4 N sideways at the tool, 7 mm/s off-axis; control/friction_residual.py)",
    )
    friction_learning_time: PositiveFloat = Field(
        5.0, description="time constant of the learning's exponential mean [s of motion]"
    )
    friction_learning_speed: PositiveFloat = Field(
        0.05, description="a tick is learned from only when some joint moves faster [rad/s]"
    )
    friction_learning_limit: float = Field(
        0.25,
        ge=0.0,
        le=1.0,
        description="the correction stays within this fraction of the model's own friction "
        "at the joint's speed (a bad fit cannot become a push)",
    )
    standstill_speed: PositiveFloat = Field(
        0.01, description="every joint slower than this [rad/s] counts as standstill"
    )
    tool_frame: str | None = Field(None, description="URDF frame; None = robot.tool_frame")
    payload: PayloadConfig = Field(default_factory=PayloadConfig)
    enable_input: EnableInputConfig = Field(default_factory=EnableInputConfig)

    @model_validator(mode="after")
    def _check(self) -> DragConfig:
        if self.max_tool_speed > ISO_REDUCED_SPEED:
            raise ValueError(
                f"max_tool_speed = {self.max_tool_speed} m/s is above the hand-guiding reduced "
                f"speed of ISO 10218-1 ({ISO_REDUCED_SPEED} m/s)"
            )
        if self.joint_mass is not None and self.joint_damping is not None:
            if len(self.joint_mass) != len(self.joint_damping):
                raise ValueError(
                    f"joint_mass has {len(self.joint_mass)} entries, joint_damping has "
                    f"{len(self.joint_damping)}"
                )
        if not (self.unlock.x or self.unlock.y or self.unlock.z or self.unlock.rotation):
            raise ValueError("unlock: every axis is locked, nothing could be dragged")
        return self

    def joint_gains(self, n: int) -> tuple[list[float], list[float]]:
        """(M_a, B_a) per joint for the joint-space variant."""
        m = self.joint_mass if self.joint_mass is not None else [0.3] * n
        b = self.joint_damping if self.joint_damping is not None else [20.0] * n
        return list(m), list(b)

    def check_rate(self, rate_hz: float, n: int) -> None:
        """Raise ValueError when the admittance is not a stable, non-oscillating discrete
        filter at ``rate_hz``.

        The controllers integrate M·v' + B·v = F by explicit Euler: v_k+1 = (1 - B·dt/M)·v_k
        + dt/M·F. The pole 1 - B·dt/M is stable for B·dt/M < 2 and free of sign-alternating
        ringing for B·dt/M < 1; we require the latter (a hand feels ringing as buzz), with the
        largest damping used, k·B_a (k = release_damping).
        """
        dt = 1.0 / rate_hz
        pairs = [
            ("mass/damping", self.mass, self.damping),
            ("rotational_mass/rotational_damping", self.rotational_mass, self.rotational_damping),
        ]
        if self.space == "joint" or self.joint_mass is not None or self.joint_damping is not None:
            jm, jb = self.joint_gains(n)
            if len(jm) != n or len(jb) != n:
                raise ValueError(
                    f"joint_mass/joint_damping have {len(jm)}/{len(jb)} entries, expected {n}"
                )
            pairs += [(f"joint_mass[{i}]/joint_damping[{i}]", jm[i], jb[i]) for i in range(n)]
        for name, m, b in pairs:
            ratio = b * self.release_damping * dt / m
            if ratio >= 1.0:
                raise ValueError(
                    f"{name}: k·B_a·dt/M_a = {self.release_damping:g}·{b:g}·{dt:g}/{m:g} = "
                    f"{ratio:.3g} at {rate_hz:g} Hz (k = release_damping); explicit Euler needs "
                    f"< 1 (raise M_a above {self.release_damping * b * dt:g} or lower B_a)"
                )
