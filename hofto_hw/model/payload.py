"""A held load in the model: a point mass at the tool added to the last link.

With the configured payload in the model, the observers explain the load's gravity and
inertia, so a held load does not look like a contact.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from hofto_hw.model.robot import RobotModel


def add_payload(model: RobotModel, mass: float, com: tuple[float, float, float]) -> RobotModel:
    """Add ``mass`` [kg] at ``com`` [m] (tool frame) to ``model`` in place; returns it.

    The load is a point mass (no rotational inertia of its own) on the tool frame's parent
    joint; the model's tool frame is unchanged.
    """
    if mass <= 0.0:
        return model
    pm = model.pin_model
    frame = pm.frames[model.tool_frame_id]
    joint = frame.parentJoint
    com_joint = frame.placement.act(np.asarray(com, dtype=float))
    load = pin.Inertia(float(mass), com_joint, np.zeros((3, 3)))
    pm.inertias[joint] = pm.inertias[joint] + load
    return model
