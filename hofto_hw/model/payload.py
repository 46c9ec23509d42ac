"""A payload (tool or load) rigidly attached to the tool frame, added to the last link.

``payload:`` in the robot config (and the block ``hofto-hw payload identify`` writes):

.. code-block:: yaml

    payload:
      mass: 2.6                 # [kg]
      com: [0.0, 0.0, 0.05]     # centre of mass [m] in the tool frame
      inertia: [Ixx, Ixy, Iyy, Ixz, Iyz, Izz]   # optional, about the com, tool axes [kg·m²]

:func:`apply_payload` adds it to the inertia of the link that carries the tool frame (pinocchio
``Inertia`` moved by the frame's placement), so M(q), g(q) and C of every workspace include it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from hofto_hw.errors import ModelError
from hofto_hw.model.robot import RobotModel


@dataclass(frozen=True)
class Payload:
    """mass [kg], com (3,) [m] in the tool frame, inertia (6,) about the com in pinocchio order
    Ixx, Ixy, Iyy, Ixz, Iyz, Izz [kg·m²] (zeros = point mass)."""

    mass: float
    com: tuple[float, float, float]
    inertia: tuple[float, float, float, float, float, float] = (0.0,) * 6

    def __post_init__(self) -> None:
        values = [self.mass, *self.com, *self.inertia]
        if not all(np.isfinite(values)) or self.mass < 0.0:
            raise ModelError(f"payload: mass must be finite and >= 0 kg, got {self.mass}")


def payload_inertia(model: RobotModel, payload: Payload) -> pin.Inertia:
    """The payload's spatial inertia expressed in the frame of the tool's parent joint."""
    ixx, ixy, iyy, ixz, iyz, izz = payload.inertia
    rot = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    local = pin.Inertia(float(payload.mass), np.asarray(payload.com, dtype=float), rot)
    frame = model.pin_model.frames[model.tool_frame_id]
    return frame.placement.act(local)


def apply_payload(model: RobotModel, payload: Payload) -> None:
    """Add ``payload`` to the inertia of the link carrying the tool frame (in place) and
    remember it (``model.payload``): loading a parameters file afterwards re-applies it."""
    joint = model.pin_model.frames[model.tool_frame_id].parentJoint
    if joint == 0:
        raise ModelError(f"{model.name}: the tool frame is not on a moving link")
    model.pin_model.inertias[joint] = model.pin_model.inertias[joint] + payload_inertia(
        model, payload
    )
    model.payload = payload
    model.mark_changed()


def payload_from_config(cfg: object) -> Payload:
    """A :class:`Payload` from a ``PayloadConfig`` section (hofto_hw/config/payload.py)."""
    inertia = (0.0,) * 6 if cfg.inertia is None else tuple(cfg.inertia)  # type: ignore[attr-defined]
    return Payload(float(cfg.mass), tuple(cfg.com), inertia)  # type: ignore[attr-defined,arg-type]
