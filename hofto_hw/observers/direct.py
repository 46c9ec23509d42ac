"""Direct estimation, eq. (2): tau_ext_hat = M(q)·qdd + C·qd + g + f - tau.

qdd is not measured: it is the backward difference of measured velocity, (qd_k - qd_{k-1})/dt,
optionally through a first-order low-pass of cutoff ``accel_filter_hz`` (discretised with
alpha = dt / (dt + 1/(2π·fc))). The difference amplifies noise (the paper's point); the filter
trades it for delay.
"""

from __future__ import annotations

import math

import numpy as np

from hofto_hw.model.robot import RobotModel
from hofto_hw.model.snapshot import DynamicsSnapshot, Needs
from hofto_hw.observers.base import SampleGuard, SnapshotUpdate


class DirectObserver(SnapshotUpdate):
    """Eq. (2). Its model term, RNEA at its own filtered qdd, depends on the observer's state,
    so it needs nothing from the tick's snapshot but the sample (no compiled kernel: one
    pinocchio call and a few array operations)."""

    name = "direct"
    needs = Needs.NONE

    def __init__(self, model: RobotModel, accel_filter_hz: float | None = None) -> None:
        self.model = model
        self.data = model.create_data()
        self.n = model.n
        self.accel_filter_hz = accel_filter_hz
        self._qd_prev = np.zeros(self.n)
        self._qdd = np.zeros(self.n)
        self._raw = np.zeros(self.n)
        self._out = np.zeros(self.n)
        self._started = False
        self._guard = SampleGuard(self.n)
        self._own_snapshot(model)

    def reset(self, q: np.ndarray, qd: np.ndarray) -> None:
        self.data.reset_friction_state()  # held friction: a new run has no memory
        np.copyto(self._qd_prev, qd)
        self._qdd.fill(0.0)
        self._started = True

    def update_snapshot(self, snap: DynamicsSnapshot, dt: float) -> np.ndarray:
        if not self._guard.usable(snap, dt):
            return self._guard.nan()
        q, qd, tau = snap.q, snap.qd, snap.tau
        if not self._started:
            self.reset(q, qd)
        raw = self._raw
        np.subtract(qd, self._qd_prev, out=raw)
        np.divide(raw, dt, out=raw)
        np.copyto(self._qd_prev, qd)
        if self.accel_filter_hz is None:
            np.copyto(self._qdd, raw)
        else:
            alpha = dt / (dt + 1.0 / (2.0 * math.pi * self.accel_filter_hz))
            np.subtract(raw, self._qdd, out=raw)
            np.multiply(raw, alpha, out=raw)
            np.add(self._qdd, raw, out=self._qdd)
        out = self.data.inverse_dynamics(q, qd, self._qdd, out=self._out)
        np.subtract(out, tau, out=out)
        return out
