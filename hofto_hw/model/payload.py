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


def blend(a: Payload, b: Payload, s: float) -> Payload:
    """The point-mass payload a fraction ``s`` in [0, 1] of the way from ``a`` to ``b``: mass
    and first moment (mass x com) interpolated linearly, so the holding torque, linear in
    them, moves linearly from a's to b's (a payload ramp's intermediate steps)."""
    m = (1.0 - s) * a.mass + s * b.mass
    h = (1.0 - s) * a.mass * np.asarray(a.com) + s * b.mass * np.asarray(b.com)
    if m > 0.0:
        c = h / m
    else:  # nothing held on either side yet: where it will be
        c = (1.0 - s) * np.asarray(a.com) + s * np.asarray(b.com)
    return Payload(float(m), (float(c[0]), float(c[1]), float(c[2])))


#: numbers of one link inertia in the native layout (hofto_hw.model.native.model_numbers):
#: mass [kg], centre of mass (3) [m], rotational inertia about it Ixx, Ixy, Iyy, Ixz, Iyz,
#: Izz [kg·m²], all in the frame of the link's joint
LINK_NUMBERS = 10


def tool_joint(model: RobotModel) -> int:
    """Index (0-based, drive order) of the joint whose link carries the tool frame."""
    joint = model.pin_model.frames[model.tool_frame_id].parentJoint
    if joint == 0:
        raise ModelError(f"{model.name}: the tool frame is not on a moving link")
    return int(joint) - 1


def inertia_numbers(inertia: pin.Inertia, out: np.ndarray | None = None) -> np.ndarray:
    """A pinocchio Inertia as :data:`LINK_NUMBERS` numbers (the native layout)."""
    v = np.zeros(LINK_NUMBERS) if out is None else out
    Ic = inertia.inertia
    v[0] = inertia.mass
    v[1:4] = inertia.lever
    v[4:] = (Ic[0, 0], Ic[1, 0], Ic[1, 1], Ic[2, 0], Ic[2, 1], Ic[2, 2])
    return v


def bare_link(model: RobotModel) -> np.ndarray:
    """The inertial parameters (10,) of the link carrying the tool without the payload
    ``model`` carries (``model.payload``; pinocchio order: m, m·c, the inertia about the joint
    frame): inertial parameters are linear in the bodies, so the payload's part subtracts."""
    Y = model.pin_model.inertias[tool_joint(model) + 1]
    pi = np.array(Y.toDynamicParameters(), dtype=float)
    if model.payload is not None:
        pi -= payload_inertia(model, model.payload).toDynamicParameters()
    return pi


def link_numbers(model: RobotModel, bare: np.ndarray, payload: Payload) -> np.ndarray:
    """The tool link's inertia with ``payload`` on it (``bare``: :func:`bare_link`), as
    :data:`LINK_NUMBERS` numbers. Computed where allocation is free (the control plane);
    the loop swaps the numbers in with :class:`LinkSwap`."""
    pi = bare + payload_inertia(model, payload).toDynamicParameters()
    return inertia_numbers(pin.Inertia.FromDynamicParameters(pi))


class LinkSwap:
    """Swaps the inertia of the link carrying the tool into ``model`` in place: the pinocchio
    model's and every native copy's (hofto_hw.model.native.NativeModel.set_inertia, same
    handle), ``model.revision`` bumped with the copies kept in step, so no workspace rebuilds
    anything. Made once off the tick; :meth:`apply` allocates no array (the loop calls it at
    a tick boundary with numbers the control plane computed, :func:`link_numbers`)."""

    def __init__(self, model: RobotModel) -> None:
        self.model = model
        self.joint = tool_joint(model)
        self.values = np.zeros(LINK_NUMBERS)  # the caller writes the numbers here
        self._lever = np.zeros(3)
        self._I = np.zeros((3, 3))

    def apply(self, payload: Payload) -> None:
        """Make ``self.values`` (see :data:`LINK_NUMBERS`) the tool link's inertia and
        ``payload`` the model's payload."""
        from hofto_hw.model import native

        v, I, m = self.values, self._I, self.model
        self._lever[:] = v[1:4]
        I[0, 0], I[1, 0], I[1, 1], I[2, 0], I[2, 1], I[2, 2] = v[4:]
        I[0, 1], I[0, 2], I[1, 2] = I[1, 0], I[2, 0], I[2, 1]
        m.pin_model.inertias[self.joint + 1] = pin.Inertia(float(v[0]), self._lever, I)
        m.payload = payload
        m.revision += 1
        native.set_link_inertia(m, self.joint, v)
