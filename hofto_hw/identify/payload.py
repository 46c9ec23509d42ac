"""Payload identification: mass and centre of mass (and optionally inertia) of a load on the
tool frame, from a recording with it attached and the identified arm.

The torque the arm's model leaves unexplained, tau − tau_model(q, qd, qdd), is what the load
adds: Y_L(q, qd, qdd)·delta, with Y_L the columns of pinocchio's joint-torque regressor of the
link carrying the tool frame and delta that link's 10 parameter changes (m, m·c, inertia about
the joint frame). Ordinary least squares over all joints and samples; std devs from
sigma²(YᵀY)⁻¹. With ``inertia=False`` only (m, m·c) are fitted (4 unknowns; short runs rarely
excite the inertia of a compact load). With ``inertia=True`` all 10 are fitted and the inertia
is moved to the centre of mass, in tool axes (I_c = I_o − m·S(c)ᵀS(c), pinocchio's
``Inertia.FromDynamicParameters``), its std devs propagated by a numerical Jacobian; the fit
reports whether the motion made the inertia identifiable: every principal moment's std dev
below ``IDENTIFIABLE_REL_STD`` of the value and the com inertia positive definite.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from hofto_hw.errors import UserError
from hofto_hw.identify.pipeline import Samples
from hofto_hw.model.robot import RobotModel

#: a principal moment of inertia counts as identified when its std dev is below this share
IDENTIFIABLE_REL_STD = 0.3
#: condition number of the column-scaled regressor above which it counts as rank deficient
RANK_DEFICIENT = 1e8


@dataclass
class PayloadEstimate:
    """mass [kg] and com (3,) [m] in the tool frame with std devs; samples used; per-joint
    RMSE [N·m] of the residual before and after the payload. With the inertia fitted:
    ``inertia`` (6,) about the com in tool axes, pinocchio order Ixx, Ixy, Iyy, Ixz, Iyz, Izz
    [kg·m²] with ``inertia_std``, ``condition`` of the column-scaled regressor, and
    ``identifiable`` (see the module notes)."""

    mass: float
    mass_std: float
    com: np.ndarray
    com_std: np.ndarray
    samples: int
    rmse_before: np.ndarray
    rmse_after: np.ndarray
    inertia: np.ndarray | None = None
    inertia_std: np.ndarray | None = None
    condition: float = float("nan")
    identifiable: bool = False

    def as_config(self) -> dict:
        """The ``payload:`` block of a robot config (with the inertia when identifiable)."""
        block: dict = {"mass": float(self.mass), "com": [float(c) for c in self.com]}
        if self.inertia is not None and self.identifiable:
            block["inertia"] = [float(v) for v in self.inertia]
        return block


def _com_and_inertia(x: np.ndarray, place: pin.SE3) -> np.ndarray:
    """(10,) mass, com (3,) in the tool frame, inertia about the com in tool axes (6,) from
    the 10 dynamic parameters ``x`` of the load in the joint frame."""
    tool = place.actInv(pin.Inertia.FromDynamicParameters(np.asarray(x, dtype=float)))
    i = tool.inertia
    return np.r_[tool.mass, tool.lever, i[0, 0], i[0, 1], i[1, 1], i[0, 2], i[1, 2], i[2, 2]]


def _principal_moments_identified(inertia: np.ndarray, std: np.ndarray) -> bool:
    ixx, ixy, iyy, ixz, iyz, izz = inertia
    rot = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    principal = np.linalg.eigvalsh(rot)
    # a rigid body: positive principal moments obeying the triangle inequality
    if not (np.all(principal > 0.0) and principal[0] + principal[1] >= principal[2]):
        return False
    diag = np.array([ixx, iyy, izz])
    return bool(np.all(std[[0, 2, 5]] < IDENTIFIABLE_REL_STD * np.abs(diag)))


def identify_payload(
    model: RobotModel, runs: Sequence[Samples], min_mass: float = 1e-3, inertia: bool = False
) -> PayloadEstimate:
    """Estimate the payload of ``runs`` (a model without the payload, identified arm); with
    ``inertia`` also its inertia about the com."""
    pm = model.pin_model
    frame = pm.frames[model.tool_frame_id]
    joint = frame.parentJoint
    cols = slice(10 * (joint - 1), 10 * (joint - 1) + (10 if inertia else 4))
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
    s2 = float(e @ e) / max(Y.shape[0] - x.size, 1)
    scale = np.linalg.norm(Y, axis=0)
    condition = float(np.linalg.cond(Y / np.where(scale > 0, scale, 1.0)))
    cov = s2 * np.linalg.pinv(Y.T @ Y)
    m, h = float(x[0]), x[1:4]
    if m < min_mass:
        raise UserError(f"payload identify: estimated mass {m:.3g} kg: no payload in these data")
    # com in the joint frame c_J = h/m (first-order propagation), then into the tool frame
    c_joint = h / m
    J = np.hstack([-h[:, None] / m**2, np.eye(3) / m])
    cov_c = J @ cov[:4, :4] @ J.T
    place = frame.placement
    com = place.rotation.T @ (c_joint - place.translation)
    cov_tool = place.rotation.T @ cov_c @ place.rotation
    n = model.n
    res_b = np.concatenate(rs)
    res_a = e.reshape(-1, n)
    extra: dict = {"condition": condition}
    if inertia:
        place = frame.placement
        y0 = _com_and_inertia(x, place)
        jac = np.zeros((10, 10))
        for i in range(10):
            step = 1e-6 * max(1.0, abs(x[i]))
            dx = np.zeros(10)
            dx[i] = step
            jac[:, i] = (_com_and_inertia(x + dx, place) - y0) / step
        cov_y = jac @ cov @ jac.T
        std_y = np.sqrt(np.maximum(np.diag(cov_y), 0.0))
        if not condition < RANK_DEFICIENT:  # unexcited columns: pinv's zeros are no std dev
            std_y[4:] = np.inf
        com, com_std = y0[1:4], std_y[1:4]
        cov_tool = np.diag(com_std**2)
        extra.update(
            inertia=y0[4:],
            inertia_std=std_y[4:],
            identifiable=_principal_moments_identified(y0[4:], std_y[4:]),
        )
    return PayloadEstimate(
        mass=m,
        mass_std=float(np.sqrt(cov[0, 0])),
        com=com,
        com_std=np.sqrt(np.maximum(np.diag(cov_tool), 0.0)),
        samples=res_b.shape[0],
        rmse_before=np.sqrt(np.mean(res_b**2, axis=0)),
        rmse_after=np.sqrt(np.mean(res_a**2, axis=0)),
        **extra,
    )
