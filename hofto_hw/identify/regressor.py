"""The standard regressor H_s(q, qd, qdd) of eq. (13): tau = H_s·theta_s.

Standard parameters, 14 per joint (Remark 2), laid out in blocks, s = 14·n columns:

- ``[0, 10n)``: rigid body, link j's 10 parameters in pinocchio order
  m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz (inertia about the joint frame origin);
- ``[10n, 11n)``: reflected rotor inertia Ia_j [kg·m²] (column qdd_j on row j);
- ``[11n, 12n)``: Coulomb friction Fc_j [N·m] (column s(qd_j), s = tanh(qd/v_s) or sign);
- ``[12n, 13n)``: viscous friction Fv_j [N·m·s/rad] (column qd_j);
- ``[13n, 14n)``: torque offset B_j [N·m] (column 1);
- optional ``[14n, 15n)``: Stribeck gap S_j = Fs_j − Fc_j [N·m] (column
  exp(−(qd_j/vs_j)²)·s(qd_j), vs_j the given Stribeck velocity [rad/s]).

Stacked regressors are sample-major: row ``k·n + j`` is joint j at sample k.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from hofto_hw.errors import UserError

N_RIGID = 10
N_PER_JOINT = 14
RIGID_NAMES = ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")
EXTRA_NAMES = ("Ia", "Fc", "Fv", "B")
STRIBECK_NAME = "S"


def standard_names(joint_names: list[str], stribeck: bool = False) -> list[str]:
    """Names of the 14·n (15·n with Stribeck) standard parameters, e.g. ``elbow_joint.Ixx``,
    ``elbow_joint.Fc``, ``elbow_joint.S``."""
    names = [f"{j}.{p}" for j in joint_names for p in RIGID_NAMES]
    for p in EXTRA_NAMES + ((STRIBECK_NAME,) if stribeck else ()):
        names += [f"{j}.{p}" for j in joint_names]
    return names


def standard_parameters(
    inertial: np.ndarray,
    rotor_inertia: np.ndarray,
    coulomb: np.ndarray,
    viscous: np.ndarray,
    bias: np.ndarray,
    stribeck_gap: np.ndarray | None = None,
) -> np.ndarray:
    """Pack the blocks into theta_s, shape (14·n,) or (15·n,) with ``stribeck_gap``."""
    blocks = [inertial, rotor_inertia, coulomb, viscous, bias]
    if stribeck_gap is not None:
        blocks.append(stribeck_gap)
    return np.concatenate(blocks).astype(float)


def split_standard(theta: np.ndarray, n: int) -> dict[str, np.ndarray]:
    """Inverse of :func:`standard_parameters`: inertial (10n,), rotor, coulomb, viscous, bias
    and, for 15·n entries, stribeck_gap (n,)."""
    r = N_RIGID * n
    out = {
        "inertial": theta[:r].copy(),
        "rotor_inertia": theta[r : r + n].copy(),
        "coulomb": theta[r + n : r + 2 * n].copy(),
        "viscous": theta[r + 2 * n : r + 3 * n].copy(),
        "bias": theta[r + 3 * n : r + 4 * n].copy(),
    }
    if theta.size == (N_PER_JOINT + 1) * n:
        out["stribeck_gap"] = theta[r + 4 * n :].copy()
    return out


class Regressor:
    """Evaluates H_s for one pinocchio model (own ``Data``), friction sign smoothed by v_s.

    ``smooth_velocity`` v_s [rad/s]: s(qd) = tanh(qd / v_s); 0 gives the hard sign (then
    noise at standstill becomes a ±Fc square wave on real data). ``stribeck_velocity`` vs
    (n,) [rad/s] adds the Stribeck-gap columns.
    """

    def __init__(
        self,
        pin_model: pin.Model,
        smooth_velocity: float = 0.0,
        stribeck_velocity: np.ndarray | None = None,
    ) -> None:
        self.model = pin_model
        self.data = pin_model.createData()
        self.n = pin_model.nv
        self.smooth_velocity = float(smooth_velocity)
        self.stribeck_velocity = (
            None if stribeck_velocity is None else np.asarray(stribeck_velocity, dtype=float)
        )
        if self.stribeck_velocity is not None and (
            self.stribeck_velocity.shape != (self.n,) or np.any(self.stribeck_velocity <= 0)
        ):
            raise UserError(f"regressor: stribeck_velocity needs {self.n} values > 0 [rad/s]")
        self.n_std = (N_PER_JOINT + (self.stribeck_velocity is not None)) * self.n

    def friction_sign(self, qd: np.ndarray) -> np.ndarray:
        """s(qd), same shape as ``qd``."""
        if self.smooth_velocity > 0.0:
            return np.tanh(np.asarray(qd) / self.smooth_velocity)
        return np.sign(qd)

    def stack(
        self,
        q: np.ndarray,
        qd: np.ndarray,
        qdd: np.ndarray,
        out: np.ndarray | None = None,
    ) -> np.ndarray:
        """Stacked H_s over N samples: q, qd, qdd of shape (N, n) -> (N·n, 14·n).

        ``out`` (N·n, 14·n) is filled in place when given.
        """
        q = np.asarray(q, dtype=float)
        qd = np.asarray(qd, dtype=float)
        qdd = np.asarray(qdd, dtype=float)
        n = self.n
        if q.ndim != 2 or q.shape[1] != n or qd.shape != q.shape or qdd.shape != q.shape:
            raise UserError(
                f"regressor: q, qd, qdd must all have shape (N, {n}); "
                f"got {q.shape}, {qd.shape}, {qdd.shape}"
            )
        N = q.shape[0]
        H = np.zeros((N * n, self.n_std)) if out is None else out
        if out is not None:
            out.fill(0.0)
        H3 = H.reshape(N, n, self.n_std)
        r = N_RIGID * n
        fn = pin.computeJointTorqueRegressor
        model, data = self.model, self.data
        for k in range(N):
            H3[k, :, :r] = fn(model, data, q[k], qd[k], qdd[k])
        idx = np.arange(n)
        H3[:, idx, r + idx] = qdd
        sgn = self.friction_sign(qd)
        H3[:, idx, r + n + idx] = sgn
        H3[:, idx, r + 2 * n + idx] = qd
        H3[:, idx, r + 3 * n + idx] = 1.0
        if self.stribeck_velocity is not None:
            H3[:, idx, r + 4 * n + idx] = np.exp(-((qd / self.stribeck_velocity) ** 2)) * sgn
        return H
