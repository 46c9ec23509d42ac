"""Generalized-momentum observer (De Luca et al.), first order.

With p = M(q)·qd and Mdot = C + Cᵀ, eq. (1) gives p' = tau + tau_ext - f - beta with
beta(q, qd) = g(q) - C(q,qd)ᵀ·qd. The residual

    r(t) = K_O·( p(t) - p(0) - ∫ (tau - f - beta + r) dt )

obeys r' = K_O·(tau_ext - r): a first-order low-pass of the external torque with bandwidth
K_O [1/s] per joint, with no acceleration needed. The integral is forward Euler with the
residual of the previous tick.
"""

from __future__ import annotations

import numpy as np

from hofto_hw.model.robot import RobotModel
from hofto_hw.observers.base import SampleGuard, per_joint


class MomentumObserver:
    name = "momentum"

    def __init__(self, model: RobotModel, gain: np.ndarray) -> None:
        n = model.n
        self.model = model
        self.data = model.create_data()
        self.n = n
        self.gain = per_joint(gain, n, "momentum.gain")
        self.integral = np.zeros(n)
        self.p0 = np.zeros(n)
        self.r = np.zeros(n)
        self._p = np.zeros(n)
        self._tmp = np.zeros(n)
        self._ct_qd = np.zeros(n)
        self._guard = SampleGuard(self.n)

    def reset(self, q: np.ndarray, qd: np.ndarray) -> None:
        self.data.reset_friction_state()  # held friction: a new run has no memory
        np.dot(self.data.mass_matrix(q), qd, out=self.p0)
        self.integral.fill(0.0)
        self.r.fill(0.0)

    def update(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray, dt: float) -> np.ndarray:
        if not self._guard.finite(q, qd, tau, dt):
            return self._guard.nan()
        m = self.data
        tmp = self._tmp
        np.dot(m.coriolis_matrix(q, qd).T, qd, out=self._ct_qd)
        np.subtract(tau, m.friction_torque(qd), out=tmp)
        np.subtract(tmp, m.gravity(q), out=tmp)
        np.add(tmp, self._ct_qd, out=tmp)  # tau - f - beta
        np.add(tmp, self.r, out=tmp)
        np.multiply(tmp, dt, out=tmp)
        np.add(self.integral, tmp, out=self.integral)
        np.dot(m.mass_matrix(q), qd, out=self._p)
        np.subtract(self._p, self.p0, out=tmp)
        np.subtract(tmp, self.integral, out=tmp)
        np.multiply(self.gain, tmp, out=self.r)
        return self.r
