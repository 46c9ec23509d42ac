"""Super-twisting (STA) observer in the form of the paper's Remark 7.

    e = q - z1
    z1' = z2 + l1·|e|^(1/2)·sign(e)
    z2' = a(q, qd, tau) + z3 + l2·|e|^(1/2)·sign(e)
    z3' = l3·sign(e)
    tau_ext_hat = M(q)·z3

i.e. eq. (17) with n = 1 and powers (1/2, 1/2, 0). The sliding-mode term l3·sign(e)
integrates to the disturbance; it can only track disturbances with a bounded first
derivative (the paper's motivation for higher orders). Written on its own, not through
HoftoCore, so that the equivalence test compares two implementations.
Discretisation: explicit Euler at the sampling instants; with ``substeps`` > 1, q is
interpolated linearly between samples and a is held (as HOFTO's). The arithmetic is
:mod:`hofto_hw.observers.kernels`' (``euler_step`` with ``sta``; the numpy reference is in
tests/hofto_hw/observers/reference.py).
"""

from __future__ import annotations

import numpy as np

from hofto_hw import jit
from hofto_hw.model.robot import RobotModel
from hofto_hw.model.snapshot import DynamicsSnapshot, Needs
from hofto_hw.observers import kernels
from hofto_hw.observers.base import SampleGuard, SnapshotUpdate, per_joint


class StaObserver(SnapshotUpdate):
    """STA on a robot: tau_ext_hat = M(q)·z3; one ``kernels.euler_update`` call per update
    (``backend``: see :mod:`hofto_hw.observers.base`)."""

    name = "sta"
    needs = Needs.ACCEL | Needs.MASS

    def __init__(
        self,
        model: RobotModel,
        l1: np.ndarray,
        l2: np.ndarray,
        l3: np.ndarray,
        substeps: int = 1,
        backend: jit.Backend = "auto",
    ) -> None:
        n = model.n
        self.model = model
        self.n = n
        self.gains = np.vstack(
            [per_joint(l1, n, "sta.l1"), per_joint(l2, n, "sta.l2"), per_joint(l3, n, "sta.l3")]
        )
        self.l1, self.l2, self.l3 = self.gains
        self.substeps = int(substeps)
        self.z = np.zeros((3, n))
        self.z1, self.z2, self.z3 = self.z
        self.prev = np.zeros(n)  # the previous sample of q
        self._out = np.zeros(n)
        self._guard = SampleGuard(self.n)
        self._own_backend(model, backend, kernels.euler_update)

    def _warm(self) -> None:
        snap, n = self.snapshot, self.n
        kernels.euler_update(
            self.z.copy(), self.gains, np.zeros(n), np.zeros(n), snap.accel, 1e-3, 1, True,
            snap.M, np.zeros(n),
        )  # fmt: skip

    def reset(self, q: np.ndarray, qd: np.ndarray) -> None:
        self.snapshot.reset_memory()  # held friction: a new run has no memory
        self.z1[:] = q
        self.z2[:] = qd
        self.z3.fill(0.0)
        self.prev[:] = q

    def update_snapshot(self, snap: DynamicsSnapshot, dt: float) -> np.ndarray:
        if not self._guard.usable(snap, dt):
            return self._guard.nan()
        z, h, sub = self.z, dt / self.substeps, self.substeps
        self._kernel(z, self.gains, snap.q, self.prev, snap.accel, h, sub, True, snap.M, self._out)
        return self._out
