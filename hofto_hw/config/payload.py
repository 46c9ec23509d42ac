"""The one payload model of every config section that names a load at the tool.

``robot.payload`` is the tool permanently mounted (identified by ``hofto-hw payload
identify``; every command's model carries it), ``safety.payload`` the load the controller
holds during a run, ``run.simulated_payload`` what the simulated arm really holds, and
``drag.payload`` a load the observers' model does not include (its weight is taken off the
drag wrench). The model side is hofto_hw/model/payload.py.
"""

from __future__ import annotations

from pydantic import Field

from hofto_hw.config.base import FileModel, NonNegFloat, PositiveFloat


class PayloadConfig(FileModel):
    """``mass`` [kg] at ``com`` [m] in the tool frame; optional ``inertia`` about the com in
    tool axes, pinocchio order Ixx, Ixy, Iyy, Ixz, Iyz, Izz [kg·m²] (None = point mass)."""

    mass: NonNegFloat = Field(0.0, description="payload mass [kg]")
    com: tuple[float, float, float] = Field(
        (0.0, 0.0, 0.0), description="centre of mass in the tool frame [m]"
    )
    inertia: tuple[float, float, float, float, float, float] | None = Field(
        None, description="about the com, tool axes: Ixx, Ixy, Iyy, Ixz, Iyz, Izz [kg·m²]"
    )


class RatedPayload(FileModel):
    """``robot.rated_payload``: the load the arm is rated for, the bounds a payload set at run
    time (``Robot.set_payload``, ``hofto-hw payload set``) must keep: ``mass`` [kg] at most,
    its centre of mass at most ``com_max`` [m] from the tool frame's origin, its holding
    torque (the arm's static gravity torque with it, here and at the worst pose the joint
    limits allow) at most ``holding_fraction`` of each joint's torque limit; a new payload
    is ramped in over ``ramp_s`` [s] (the feed-forward does not step)."""

    mass: PositiveFloat = Field(description="rated payload [kg]")
    com_max: PositiveFloat = Field(description="largest distance of its com from the tool [m]")
    holding_fraction: float = Field(
        1.0,
        gt=0.0,
        le=1.0,
        description="largest holding torque of a payload set at run time, as a fraction of "
        "each joint's torque limit (robot.limits.torque, else the URDF's effort)",
    )
    ramp_s: float = Field(
        0.3,
        ge=0.0,
        le=5.0,
        description="time [s] over which a payload set at run time is ramped in (from the "
        "one held, by intermediate payloads the loop takes at standstill); 0: one step",
    )
