"""Payload identification: mass and centre of mass (and optionally inertia) of a load on the
tool frame, from a recording with it attached and the identified arm.

The torque the arm's model leaves unexplained, tau − tau_model(q, qd, qdd), is what the load
adds: Y_L(q, qd, qdd)·delta, with Y_L the columns of pinocchio's joint-torque regressor of the
link carrying the tool frame and delta that link's 10 parameter changes (m, m·c, inertia about
the joint frame). Ordinary least squares over all joints and samples; std devs from
sigma²(YᵀY)⁻¹. With ``inertia=False`` only (m, m·c) are fitted (4 unknowns; short runs rarely
excite the inertia of a compact load).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from hofto_hw.errors import UserError
from hofto_hw.identify.pipeline import Samples
from hofto_hw.model.robot import RobotModel


@dataclass
class PayloadEstimate:
    """mass [kg] and com (3,) [m] in the tool frame with std devs; samples used; per-joint
    RMSE [N·m] of the residual before and after the payload."""

    mass: float
    mass_std: float
    com: np.ndarray
    com_std: np.ndarray
    samples: int
    rmse_before: np.ndarray
    rmse_after: np.ndarray

    def as_config(self) -> dict:
        """The ``payload:`` block of a robot config."""
        return {"mass": float(self.mass), "com": [float(c) for c in self.com]}


def identify_payload(
    model: RobotModel, runs: Sequence[Samples], min_mass: float = 1e-3
) -> PayloadEstimate:
    """Estimate the payload of ``runs`` (a model without the payload, identified arm)."""
    pm = model.pin_model
    frame = pm.frames[model.tool_frame_id]
    joint = frame.parentJoint
    cols = slice(10 * (joint - 1), 10 * (joint - 1) + 4)
    data = model.create_data()
    pdata = pm.createData()
    Ys, rs = [], []
    for run in runs:
        data.reset_friction_state()
        pred = np.empty_like(run.tau)
        for k in range(run.tau.shape[0]):
            data.inverse_dynamics(run.q[k], run.qd[k], run.qdd[k], out=pred[k])
            Y = pin.computeJointTorqueRegressor(pm, pdata, run.q[k], run.qd[k], run.qdd[k])
            Ys.append(Y[:, cols].copy())
        rs.append(run.tau - pred)
    Y = np.vstack(Ys)
    r = np.concatenate(rs).reshape(-1)
    if Y.shape[0] < 40:
        raise UserError(f"payload identify: {Y.shape[0] // model.n} samples are too few")
    x, *_ = np.linalg.lstsq(Y, r, rcond=None)
    e = r - Y @ x
    s2 = float(e @ e) / max(Y.shape[0] - 4, 1)
    cov = s2 * np.linalg.inv(Y.T @ Y)
    m, h = float(x[0]), x[1:4]
    if m < min_mass:
        raise UserError(f"payload identify: estimated mass {m:.3g} kg: no payload in these data")
    # com in the joint frame c_J = h/m (first-order propagation), then into the tool frame
    c_joint = h / m
    J = np.hstack([-h[:, None] / m**2, np.eye(3) / m])
    cov_c = J @ cov @ J.T
    place = frame.placement
    com = place.rotation.T @ (c_joint - place.translation)
    cov_tool = place.rotation.T @ cov_c @ place.rotation
    n = model.n
    res_b = np.concatenate(rs)
    res_a = e.reshape(-1, n)
    return PayloadEstimate(
        mass=m,
        mass_std=float(np.sqrt(cov[0, 0])),
        com=com,
        com_std=np.sqrt(np.maximum(np.diag(cov_tool), 0.0)),
        samples=res_b.shape[0],
        rmse_before=np.sqrt(np.mean(res_b**2, axis=0)),
        rmse_after=np.sqrt(np.mean(res_a**2, axis=0)),
    )
