"""Disturbance observer (DOB) in the style of Sariyildiz and Ohnishi (paper ref. [10]).

The plant is split into a nominal, decoupled inertia Jn (constant, diagonal) and everything
else. With a first-order low-pass G(s) = g/(s + g) per joint, the reaction-torque form is

    tau_ext_hat = G(s)·[ Jn·qdd + C(q,qd)·qd + g(q) + f(qd) - tau ]

and qdd is never formed: G(s)·Jn·s·qd = g·Jn·qd - G(s)·g·Jn·qd. So, exactly:

    w' = g·( g·Jn·qd + tau - C·qd - g(q) - f - w )
    tau_ext_hat = g·Jn·qd - w

The inertia mismatch (M(q) - Jn)·qdd and the filter lag are the DOB's error sources; the
paper's comparison uses such a DOB. Jn defaults to diag M(home). The filter is discretised
exactly for a held input: w += (1 - exp(-g·dt))·(u - w). The arithmetic is
:mod:`hofto_hw.observers.kernels`' (``dob_update``; the numpy reference is in
tests/hofto_hw/observers/reference.py).
"""

from __future__ import annotations

import numpy as np

from hofto_hw import jit
from hofto_hw.model.robot import RobotModel
from hofto_hw.model.snapshot import DynamicsSnapshot, Needs
from hofto_hw.observers import kernels
from hofto_hw.observers.base import SampleGuard, SnapshotUpdate, per_joint


class DobObserver(SnapshotUpdate):
    """tau_ext_hat = g·Jn·qd - w; one ``kernels.dob_update`` call per update (``backend``:
    see :mod:`hofto_hw.observers.base`)."""

    name = "dob"
    needs = Needs.NLE | Needs.FRICTION

    def __init__(
        self,
        model: RobotModel,
        cutoff: np.ndarray,
        nominal_inertia: np.ndarray | None = None,
        backend: jit.Backend = "auto",
    ) -> None:
        n = model.n
        self.model = model
        self.n = n
        self.cutoff = per_joint(cutoff, n, "dob.cutoff")
        if nominal_inertia is None:
            nominal_inertia = np.diag(model.create_data().mass_matrix(model.home)).copy()
        self.jn = per_joint(nominal_inertia, n, "dob.nominal_inertia")
        self._gj = self.cutoff * self.jn  # g·Jn
        self.w = np.zeros(n)
        #: [dt [s] the pole was computed for (< 0: none yet)], alpha = 1 - exp(-g·dt) (n,)
        self.work = np.zeros((2, n))
        self.work[0, 0] = -1.0
        self._out = np.zeros(n)
        self._guard = SampleGuard(self.n)
        self._own_backend(model, backend, kernels.dob_update)

    def _warm(self) -> None:
        s, n = self.snapshot, self.n
        kernels.dob_update(
            self._gj, self.cutoff, np.zeros(n), self.work.copy(), s.qd, s.tau, s.nle, s.f, 1e-3,
            np.zeros(n),
        )  # fmt: skip

    def reset(self, q: np.ndarray, qd: np.ndarray) -> None:
        self.snapshot.reset_memory()  # held friction: a new run has no memory
        np.multiply(self._gj, qd, out=self.w)  # tau_ext_hat starts at 0

    def update_snapshot(self, snap: DynamicsSnapshot, dt: float) -> np.ndarray:
        if not self._guard.usable(snap, dt):
            return self._guard.nan()
        self._kernel(
            self._gj, self.cutoff, self.w, self.work, snap.qd, snap.tau, snap.nle, snap.f, dt,
            self._out,
        )  # fmt: skip
        return self._out
