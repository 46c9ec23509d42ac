"""The standard regressor H_s(q, qd, qdd) of eq. (13): tau = H_s·theta_s.

Standard parameters, 14 per joint (Remark 2), laid out in blocks, s = 14·n columns:

- ``[0, 10n)``: rigid body, link j's 10 parameters in pinocchio order
  m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz (inertia about the joint frame origin);
- ``[10n, 11n)``: reflected rotor inertia Ia_j [kg·m²] (column qdd_j on row j);
- ``[11n, 12n)``: Coulomb friction Fc_j [N·m] (column s(qd_j), s = tanh(qd/v_s) or sign);
- ``[12n, 13n)``: viscous friction Fv_j [N·m·s/rad] (column qd_j);
- ``[13n, 14n)``: torque offset B_j [N·m] (column 1);
- optional ``[14n, 15n)``: Stribeck gap S_j = Fs_j − Fc_j [N·m] (column
  exp(−(qd_j/vs_j)²)·s(qd_j), vs_j the given Stribeck velocity [rad/s]);
- optional next block: held friction H_j = Fh_j [N·m] (column h_j·exp(−(qd_j/v_h)²), h the
  held sign of the last velocity outside the band v_h, computed causally over each recording:
  :func:`held_sign_series`; see ``hofto_hw.model.friction``);
- optional last block: quadratic friction Q_j = Fq_j [N·m·s²/rad²] (column qd_j·|qd_j|).

Stacked regressors are sample-major: row ``k·n + j`` is joint j at sample k.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from hofto_hw.errors import UserError
from hofto_hw.model.friction import FEATURES, FrictionParams

N_RIGID = 10
N_PER_JOINT = 14
RIGID_NAMES = ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")
EXTRA_NAMES = ("Ia", "Fc", "Fv", "B")
STRIBECK_NAME = "S"
HELD_NAME = "H"
QUADRATIC_NAME = "Q"


#: the friction feature (hofto_hw.model.friction.FEATURES) of each optional block
_BLOCK_FEATURE = {STRIBECK_NAME: "stribeck_gap", HELD_NAME: "held", QUADRATIC_NAME: "quadratic"}


def optional_names(stribeck: bool = False, held: bool = False, quadratic: bool = False) -> tuple:
    """The optional friction blocks present, in their standard order."""
    return (
        ((STRIBECK_NAME,) if stribeck else ())
        + ((HELD_NAME,) if held else ())
        + ((QUADRATIC_NAME,) if quadratic else ())
    )


def standard_names(
    joint_names: list[str], stribeck: bool = False, held: bool = False, quadratic: bool = False
) -> list[str]:
    """Names of the 14·n (+n per optional block) standard parameters, e.g.
    ``elbow_joint.Ixx``, ``elbow_joint.Fc``, ``elbow_joint.S``, ``elbow_joint.H``."""
    names = [f"{j}.{p}" for j in joint_names for p in RIGID_NAMES]
    for p in EXTRA_NAMES + optional_names(stribeck, held, quadratic):
        names += [f"{j}.{p}" for j in joint_names]
    return names


def held_sign_series(qd: np.ndarray, band: float, initial: np.ndarray | None = None) -> np.ndarray:
    """Held sign h (N, n) of a velocity sequence qd (N, n) [rad/s], in time order: h_k =
    sign(qd_k) where |qd_k| > ``band``, else h_{k-1} (``initial`` (n,), default 0). The
    friction kernel's own held memory (``FrictionParams.held_signs``)."""
    qd = np.asarray(qd, dtype=float)
    return FrictionParams.structure(qd.shape[1], held_velocity=band).held_signs(qd, initial)


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


def split_optional(theta: np.ndarray, n: int, optional: tuple) -> dict[str, np.ndarray]:
    """Like :func:`split_standard` for an explicit list of optional blocks (``optional_names``
    order): adds ``stribeck_gap``, ``held``, ``quadratic`` (n,) as present."""
    r = N_RIGID * n
    out = split_standard(theta[: r + 4 * n], n)
    keys = {STRIBECK_NAME: "stribeck_gap", HELD_NAME: "held", QUADRATIC_NAME: "quadratic"}
    for i, name in enumerate(optional):
        out[keys[name]] = theta[r + (4 + i) * n : r + (5 + i) * n].copy()
    return out


class Regressor:
    """Evaluates H_s for one pinocchio model (own ``Data``), friction sign smoothed by v_s.

    ``smooth_velocity`` v_s [rad/s]: s(qd) = tanh(qd / v_s); 0 gives the hard sign (then
    noise at standstill becomes a ±Fc square wave on real data). ``stribeck_velocity`` vs
    (n,) [rad/s] adds the Stribeck-gap columns, ``held_velocity`` v_h [rad/s] the held-friction
    columns (``held_passive``: zero while qd·h < 0, as ``FrictionParams.held_passive``),
    ``quadratic`` the qd·|qd| columns.
    """

    def __init__(
        self,
        pin_model: pin.Model,
        smooth_velocity: float = 0.0,
        stribeck_velocity: np.ndarray | None = None,
        held_velocity: float | None = None,
        quadratic: bool = False,
        held_passive: bool = False,
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
        if held_velocity is not None and not held_velocity > 0.0:
            raise UserError(f"regressor: held_velocity must be > 0 rad/s, got {held_velocity}")
        self.held_velocity = None if held_velocity is None else float(held_velocity)
        self.quadratic = bool(quadratic)
        self.held_passive = bool(held_passive)
        self.optional = optional_names(
            self.stribeck_velocity is not None, self.held_velocity is not None, self.quadratic
        )
        self.n_std = (N_PER_JOINT + len(self.optional)) * self.n
        # the friction columns are this model's features (hofto_hw.model.friction)
        self._friction = FrictionParams.structure(
            self.n,
            self.smooth_velocity,
            self.stribeck_velocity,
            self.held_velocity,
            self.quadratic,
            self.held_passive,
        )

    def stack(
        self,
        q: np.ndarray,
        qd: np.ndarray,
        qdd: np.ndarray,
        out: np.ndarray | None = None,
        held: np.ndarray | None = None,
    ) -> np.ndarray:
        """Stacked H_s over N samples: q, qd, qdd of shape (N, n) -> (N·n, n_std).

        ``out`` (N·n, n_std) is filled in place when given. ``held`` (N, n): the held sign of
        each sample (default: :func:`held_sign_series` of ``qd`` from 0), for the held
        columns; pass it when a recording is split into chunks.
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
        phi = self._friction.features(qd, held)  # (N, n, FEATURES): eq. (12)'s own terms
        blocks = ["coulomb", "viscous", "bias"]
        blocks += [_BLOCK_FEATURE[name] for name in self.optional]
        for b, name in enumerate(blocks):
            H3[:, idx, r + (1 + b) * n + idx] = phi[:, :, FEATURES.index(name)]
        return H
