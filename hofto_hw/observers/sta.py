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
interpolated linearly between samples and a is held (as HOFTO's).
"""

from __future__ import annotations

import numpy as np

from hofto_hw.model.robot import RobotModel
from hofto_hw.model.snapshot import DynamicsSnapshot, Needs
from hofto_hw.observers import kernels
from hofto_hw.observers.base import LinearHold, SampleGuard, SnapshotUpdate, per_joint


class StaObserver(SnapshotUpdate):
    name = "sta"
    needs = Needs.ACCEL | Needs.MASS

    def __init__(
        self,
        model: RobotModel,
        l1: np.ndarray,
        l2: np.ndarray,
        l3: np.ndarray,
        substeps: int = 1,
        backend: kernels.Backend = "numpy",
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
        self._e, self._sqrt, self._sgn = np.zeros(n), np.zeros(n), np.zeros(n)
        self._tmp = np.zeros(n)
        self._out = np.zeros(n)
        self._hold = LinearHold(n)
        self._guard = SampleGuard(self.n)
        self._own_backend(model, backend)

    def _warm(self) -> None:
        snap, n = self.snapshot, self.n
        kernels.sta_update(
            self.z.copy(),
            self.gains,
            np.zeros(n),
            np.zeros(n),
            snap.accel,
            1e-3,
            1,
            snap.M,
            np.zeros(n),
        )

    def reset(self, q: np.ndarray, qd: np.ndarray) -> None:
        self.snapshot.reset_memory()  # held friction: a new run has no memory
        self.z1[:] = q
        self.z2[:] = qd
        self.z3.fill(0.0)
        self._hold.reset(q)

    def update_snapshot(self, snap: DynamicsSnapshot, dt: float) -> np.ndarray:
        if not self._guard.usable(snap, dt):
            return self._guard.nan()
        h = dt / self.substeps
        a = snap.accel
        if self.backend == "numba":
            kernels.sta_update(
                self.z,
                self.gains,
                snap.q,
                self._hold.prev,
                a,
                h,
                self.substeps,
                snap.M,
                self._out,
            )
            return self._out
        e, root, sgn, tmp = self._e, self._sqrt, self._sgn, self._tmp
        z1, z2, z3, l1, l2, l3 = self.z1, self.z2, self.z3, self.l1, self.l2, self.l3
        self._hold.begin(snap.q, self.substeps)
        for _ in range(self.substeps):
            np.subtract(self._hold.next(), z1, out=e)
            np.sign(e, out=sgn)
            np.abs(e, out=root)
            np.sqrt(root, out=root)
            np.copysign(root, e, out=root)  # |e|^(1/2)·sign(e)
            # z1, z2, z3 are advanced from the same (old) state: explicit Euler.
            np.multiply(l1, root, out=tmp)
            np.add(tmp, z2, out=tmp)
            np.multiply(l2, root, out=root)
            np.add(root, z3, out=root)
            np.add(root, a, out=root)
            np.multiply(l3, sgn, out=sgn)
            np.multiply(tmp, h, out=tmp)
            np.add(z1, tmp, out=z1)
            np.multiply(root, h, out=root)
            np.add(z2, root, out=z2)
            np.multiply(sgn, h, out=sgn)
            np.add(z3, sgn, out=z3)
        self._hold.end(snap.q)
        return np.dot(snap.M, z3, out=self._out)
