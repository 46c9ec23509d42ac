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
from hofto_hw.observers.base import LinearHold, ModelTerms, SampleGuard, per_joint


class StaObserver:
    name = "sta"

    def __init__(
        self, model: RobotModel, l1: np.ndarray, l2: np.ndarray, l3: np.ndarray, substeps: int = 1
    ) -> None:
        n = model.n
        self.model = model
        self.n = n
        self.l1 = per_joint(l1, n, "sta.l1")
        self.l2 = per_joint(l2, n, "sta.l2")
        self.l3 = per_joint(l3, n, "sta.l3")
        self.substeps = int(substeps)
        self.z1, self.z2, self.z3 = np.zeros(n), np.zeros(n), np.zeros(n)
        self._e, self._sqrt, self._sgn = np.zeros(n), np.zeros(n), np.zeros(n)
        self._tmp = np.zeros(n)
        self._hold = LinearHold(n)
        self.terms = ModelTerms(model)
        self._guard = SampleGuard(self.n)

    def reset(self, q: np.ndarray, qd: np.ndarray) -> None:
        self.terms.data.reset_friction_state()  # held friction: a new run has no memory
        self.z1[:] = q
        self.z2[:] = qd
        self.z3.fill(0.0)
        self._hold.reset(q)

    def update(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray, dt: float) -> np.ndarray:
        if not self._guard.finite(q, qd, tau, dt):
            return self._guard.nan()
        a = self.terms.acceleration(q, qd, tau)
        h = dt / self.substeps
        e, root, sgn, tmp = self._e, self._sqrt, self._sgn, self._tmp
        self._hold.begin(q, self.substeps)
        for _ in range(self.substeps):
            np.subtract(self._hold.next(), self.z1, out=e)
            np.sign(e, out=sgn)
            np.abs(e, out=root)
            np.sqrt(root, out=root)
            np.multiply(root, sgn, out=root)  # |e|^(1/2)·sign(e)
            # z1, z2, z3 are advanced from the same (old) state: explicit Euler.
            np.multiply(self.l1, root, out=tmp)
            np.add(tmp, self.z2, out=tmp)
            np.multiply(self.l2, root, out=root)
            np.add(root, self.z3, out=root)
            np.add(root, a, out=root)
            np.multiply(self.l3, sgn, out=sgn)
            np.multiply(tmp, h, out=tmp)
            np.add(self.z1, tmp, out=self.z1)
            np.multiply(root, h, out=root)
            np.add(self.z2, root, out=self.z2)
            np.multiply(sgn, h, out=sgn)
            np.add(self.z3, sgn, out=self.z3)
        self._hold.end(q)
        return self.terms.torque(q, self.z3)
