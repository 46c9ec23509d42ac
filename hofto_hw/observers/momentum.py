"""Generalized-momentum observer (De Luca et al.), first order.

With p = M(q)·qd and Mdot = C + Cᵀ, eq. (1) gives p' = tau + tau_ext - f - beta with
beta(q, qd) = g(q) - C(q,qd)ᵀ·qd. The residual

    r(t) = K_O·( p(t) - p(0) - ∫ (tau - f - beta + r) dt )

obeys r' = K_O·(tau_ext - r): a first-order low-pass of the external torque with bandwidth
K_O [1/s] per joint, with no acceleration needed. The integral is forward Euler with the
residual of the previous tick. The arithmetic is :mod:`hofto_hw.observers.kernels`'
(``momentum_update``; the numpy reference is in tests/hofto_hw/observers/reference.py).
"""

from __future__ import annotations

import numpy as np

from hofto_hw import jit
from hofto_hw.model.robot import RobotModel
from hofto_hw.model.snapshot import DynamicsSnapshot, Needs
from hofto_hw.observers import kernels
from hofto_hw.observers.base import SampleGuard, SnapshotUpdate, per_joint

_FIELDS = ("gain", "p0", "integral", "r")


class MomentumObserver(SnapshotUpdate):
    """The momentum residual r [N·m]; one ``kernels.momentum_update`` call per update
    (``backend``: see :mod:`hofto_hw.observers.base`)."""

    name = "momentum"
    needs = Needs.MASS | Needs.GRAVITY | Needs.CORIOLIS_T | Needs.FRICTION

    def __init__(self, model: RobotModel, gain: np.ndarray, backend: jit.Backend = "auto") -> None:
        n = model.n
        self.model = model
        self.n = n
        #: gain, p0, integral and the residual r (n,) as one record (observers.bank passes it
        #: as one argument); the attributes are its fields
        self.record = np.zeros(1, jit.interned(np.dtype([(f, np.float64, (n,)) for f in _FIELDS])))
        self.gain, self.p0, self.integral, self.r = (self.record[0][f] for f in _FIELDS)
        self.gain[:] = per_joint(gain, n, "momentum.gain")
        self._guard = SampleGuard(self.n)
        self._reset_data = model.create_data()  # reset is off the tick
        self._own_backend(model, backend, kernels.momentum_update)

    def _warm(self) -> None:
        s, n = self.snapshot, self.n
        kernels.momentum_update(
            s.M,
            s.qd,
            s.tau,
            s.f,
            s.g,
            s.ct_qd,
            self.gain,
            self.p0,
            np.zeros(n),
            np.zeros(n),
            1e-3,
        )

    def reset(self, q: np.ndarray, qd: np.ndarray) -> None:
        self.snapshot.reset_memory()  # held friction: a new run has no memory
        np.dot(self._reset_data.mass_matrix(q), qd, out=self.p0)
        self.integral.fill(0.0)
        self.r.fill(0.0)

    def update_snapshot(self, snap: DynamicsSnapshot, dt: float) -> np.ndarray:
        if not self._guard.usable(snap, dt):
            return self._guard.nan()
        self._kernel(
            snap.M, snap.qd, snap.tau, snap.f, snap.g, snap.ct_qd, self.gain, self.p0,
            self.integral, self.r, dt,
        )  # fmt: skip
        return self.r
