"""Tool wrench from estimated joint torques: F_ext_hat = (Jᵀ)⁺·tau_ext_hat (paper eq. 34).

:class:`ToolJacobian` evaluates the tool Jacobian J (6, n) once per tick, its manipulability
w = sqrt(det(J·Jᵀ)) and one Cholesky factor of A = J·Jᵀ + λ²·I, with the damping λ rising
as w falls below a threshold (Nakamura's variable damping):

    λ² = λ0²·(1 - w/w0)²  for w < w0,  0 otherwise.

With that factor the same tick gets both damped inverses:

- the wrench of a joint torque: F = A⁻¹·J·tau = (Jᵀ)⁺·tau (exact away from singularities);
- the joint velocity of a twist: qd = Jᵀ·A⁻¹·V (damped least squares).

:class:`WrenchEstimator` adds the payload's weight correction. Twists and wrenches are in
the world-aligned frame at the tool origin: (v_x, v_y, v_z, w_x, w_y, w_z) [m/s, rad/s] and
(F_x, F_y, F_z, M_x, M_y, M_z) [N, N·m]. Per tick allocation-free: pinocchio's Jacobian is
copied into an owned buffer and LAPACK (dpotrf/dpotrs) works in place on owned buffers.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
from scipy.linalg.lapack import dpotrf, dpotrs

from hofto_hw.errors import ModelError
from hofto_hw.model.robot import RobotModel


class ToolJacobian:
    """Per-tick tool Jacobian, manipulability and damped inverses (see module docstring).

    ``tool_frame``: URDF frame (default: the model's tool frame). ``w0`` [m³]: manipulability
    below which damping starts; ``lambda0`` [m]: the damping at w = 0.
    Public after :meth:`update`: ``J`` (6, n), ``w``, ``lam2``, ``position`` (3,) [m].
    """

    def __init__(
        self,
        model: RobotModel,
        tool_frame: str | None = None,
        w0: float = 0.004,
        lambda0: float = 0.05,
    ) -> None:
        pm = model.pin_model
        frame = tool_frame or model.tool_frame
        if not pm.existFrame(frame):
            raise ModelError(f"{model.name}: drag.tool_frame: frame {frame!r} is not in the URDF")
        self.model = model
        self.data = model.create_data()
        self.frame_id = pm.getFrameId(frame)
        self.n = model.n
        self.w0 = float(w0)
        self.lam2_max = float(lambda0) ** 2
        n = self.n
        self.J = np.zeros((6, n))
        self.w = 0.0
        self.lam2 = 0.0
        self.position = np.zeros(3)
        self.rotation = np.zeros((3, 3))
        self._JJt = np.zeros((6, 6))
        self._A = np.zeros((6, 6))  # C order, symmetric: passed to LAPACK as its F-order .T
        self._b = np.zeros(6)
        self._ok = False

    def update(self, q: np.ndarray) -> float:
        """Evaluate J, w, the damping and the factor at ``q`` (n,) [rad]; returns w."""
        d = self.data
        if self.frame_id == self.model.tool_frame_id:
            d.tool_jacobian(q, out=self.J)
        else:
            np.copyto(
                self.J,
                pin.computeFrameJacobian(
                    self.model.pin_model, d.pin_data, q, self.frame_id, pin.LOCAL_WORLD_ALIGNED
                ),
            )
        # the Jacobian call placed the frame: read its pose without another kinematics pass
        placement = d.pin_data.oMf[self.frame_id]
        np.copyto(self.position, placement.translation)
        np.copyto(self.rotation, placement.rotation)
        JJt, A = self._JJt, self._A
        np.matmul(self.J, self.J.T, out=JJt)
        np.copyto(A, JJt)
        _, info = dpotrf(A.T, lower=0, clean=0, overwrite_a=1)
        if info == 0:
            prod = 1.0
            for i in range(6):
                prod *= A[i, i]
            w = abs(prod)
        else:
            w = 0.0
        self.w = w
        if w < self.w0:
            r = 1.0 - w / self.w0
            self.lam2 = self.lam2_max * r * r
            np.copyto(A, JJt)
            for i in range(6):
                A[i, i] += self.lam2
            _, info = dpotrf(A.T, lower=0, clean=0, overwrite_a=1)
        else:
            self.lam2 = 0.0
        self._ok = info == 0
        return w

    @property
    def ok(self) -> bool:
        """False when J·Jᵀ + λ²·I could not be factored (then the solves return zeros)."""
        return self._ok

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """A⁻¹·rhs for rhs (6,), in place (returns ``rhs``)."""
        if not self._ok:
            rhs.fill(0.0)
            return rhs
        _, info = dpotrs(self._A.T, rhs, lower=0, overwrite_b=1)
        return rhs

    def wrench(self, tau: np.ndarray, out: np.ndarray) -> np.ndarray:
        """(Jᵀ)⁺·tau (damped) for joint torques tau (n,) [N·m] into ``out`` (6,)."""
        np.matmul(self.J, tau, out=self._b)
        self.solve(self._b)
        np.copyto(out, self._b)
        return out

    def joint_velocity(self, twist: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Damped least squares qd = Jᵀ·A⁻¹·twist for twist (6,) into ``out`` (n,)."""
        np.copyto(self._b, twist)
        self.solve(self._b)
        np.matmul(self.J.T, self._b, out=out)
        return out


class WrenchEstimator:
    """F_ext_hat at the tool from tau_ext_hat (see module docstring).

    ``payload_mass`` [kg] at ``payload_com`` [m] (tool frame): a load the observers' model
    does not include; its weight is subtracted from the estimate. ``gravity`` [m/s²] (3,).
    After :meth:`update`: ``wrench`` (6,) [N, N·m], ``force_norm`` [N].
    """

    def __init__(
        self,
        jac: ToolJacobian,
        payload_mass: float = 0.0,
        payload_com: tuple[float, float, float] = (0.0, 0.0, 0.0),
        gravity: tuple[float, float, float] = (0.0, 0.0, -9.81),
    ) -> None:
        self.jac = jac
        self.payload_weight = float(payload_mass) * np.asarray(gravity, dtype=float)
        self.payload_com = np.asarray(payload_com, dtype=float)
        self.has_payload = payload_mass > 0.0
        self.wrench = np.zeros(6)
        self.force_norm = 0.0
        self._r = np.zeros(3)
        self._m = np.zeros(3)

    def update(self, tau_ext: np.ndarray) -> np.ndarray:
        """Wrench [N, N·m] (6,) of tau_ext (n,) [N·m]; call ``jac.update(q)`` first."""
        w = self.jac.wrench(tau_ext, self.wrench)
        if self.has_payload:
            # the load pulls down with m·g at its centre of mass: take that off
            np.matmul(self.jac.rotation, self.payload_com, out=self._r)
            f = self.payload_weight
            _cross(self._r, f, self._m)
            w[:3] -= f
            w[3:] -= self._m
        self.force_norm = norm3(w)
        return w


def norm3(x: np.ndarray, i: int = 0) -> float:
    """The Euclidean norm of x[i:i+3] (a force, moment, linear or angular speed), without a
    numpy call: the control modules' one 3-norm."""
    return math.sqrt(x[i] * x[i] + x[i + 1] * x[i + 1] + x[i + 2] * x[i + 2])


def _cross(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """out = a × b for (3,) arrays, without allocating (np.cross allocates)."""
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]
