"""Linear extended state observer (ESO), eq. (5) of the paper.

    z1' = z2 + k1·(q - z1)
    z2' = a(q, qd, tau) + z3 + k2·(q - z1)
    z3' = k3·(q - z1)
    tau_ext_hat = M(q)·z3

with a = M⁻¹·tau + F(q, qd) (eq. (4)) and diagonal gains k1 [1/s], k2 [1/s²], k3 [1/s³]. The
error polynomial is s³ + k1·s² + k2·s + k3; on a ramp of x3 it keeps the steady-state error
bound ||A⁻¹B||·zeta of eq. (10). :func:`bandwidth_gains` places all three poles at -w0.

Discretisation: explicit Euler at the sampling instants; with ``substeps`` > 1, q is
interpolated linearly between samples and a is held — exactly as HOFTO's, so that Remark 7's
equivalence holds sample by sample.
"""

from __future__ import annotations

import numpy as np

from hofto_hw.model.robot import RobotModel
from hofto_hw.model.snapshot import DynamicsSnapshot, Needs
from hofto_hw.observers import kernels
from hofto_hw.observers.base import LinearHold, SampleGuard, SnapshotUpdate, per_joint


def bandwidth_gains(w0: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """k1, k2, k3 with a triple pole at -w0 [rad/s] (Gao's bandwidth parameterisation)."""
    w0 = np.asarray(w0, dtype=float)
    return 3.0 * w0, 3.0 * w0**2, w0**3


def error_matrices(k1: float, k2: float, k3: float) -> tuple[np.ndarray, np.ndarray]:
    """A and B of the error dynamics e' = A·e + B·x3' (eq. (6)-(7)) for one joint."""
    A = np.array([[-k1, 1.0, 0.0], [-k2, 0.0, 1.0], [-k3, 0.0, 0.0]])
    B = np.array([[0.0], [0.0], [1.0]])
    return A, B


class EsoCore:
    """ESO dynamics for independent channels (arrays of shape (joints,)).

    States z (3, joints) (``z1``, ``z2``, ``z3`` are row views), gains k (3, joints)."""

    def __init__(self, k1: np.ndarray, k2: np.ndarray, k3: np.ndarray, substeps: int = 1) -> None:
        self.k = np.vstack([np.asarray(k, dtype=float) for k in (k1, k2, k3)])
        self.k1, self.k2, self.k3 = self.k
        self.substeps = int(substeps)
        j = self.k1.shape[0]
        self.z = np.zeros((3, j))
        self.z1, self.z2, self.z3 = self.z
        self._e = np.zeros(j)
        self._d1, self._d2, self._d3 = np.zeros(j), np.zeros(j), np.zeros(j)
        self._hold = LinearHold(j)

    def reset(self, y: np.ndarray, yd: np.ndarray | None = None) -> None:
        self.z1[:] = y
        self.z2[:] = 0.0 if yd is None else yd
        self.z3.fill(0.0)
        self._hold.reset(y)

    def step(self, y: np.ndarray, a: np.ndarray, dt: float) -> np.ndarray:
        h = dt / self.substeps
        e, d1, d2, d3 = self._e, self._d1, self._d2, self._d3
        z1, z2, z3, k1, k2, k3 = self.z1, self.z2, self.z3, self.k1, self.k2, self.k3
        self._hold.begin(y, self.substeps)
        for _ in range(self.substeps):
            np.subtract(self._hold.next(), z1, out=e)
            # every derivative from the old state (explicit Euler), then all states advance
            np.multiply(k1, e, out=d1)
            np.add(d1, z2, out=d1)
            np.multiply(k2, e, out=d2)
            np.add(d2, z3, out=d2)
            np.add(d2, a, out=d2)
            np.multiply(k3, e, out=d3)
            np.multiply(d1, h, out=d1)
            np.add(z1, d1, out=z1)
            np.multiply(d2, h, out=d2)
            np.add(z2, d2, out=z2)
            np.multiply(d3, h, out=d3)
            np.add(z3, d3, out=z3)
        self._hold.end(y)
        return z3

    def step_compiled(
        self, y: np.ndarray, a: np.ndarray, dt: float, M: np.ndarray, out: np.ndarray
    ) -> None:
        """:meth:`step` in one compiled kernel, then out = M·z3 [N·m] (numba required)."""
        kernels.eso_update(
            self.z, self.k, y, self._hold.prev, a, dt / self.substeps, self.substeps, M, out
        )


class EsoObserver(SnapshotUpdate):
    name = "eso"
    needs = Needs.ACCEL | Needs.MASS

    def __init__(
        self,
        model: RobotModel,
        k1: np.ndarray,
        k2: np.ndarray,
        k3: np.ndarray,
        substeps: int = 1,
        backend: kernels.Backend = "numpy",
    ) -> None:
        n = model.n
        self.model = model
        self.n = n
        self.core = EsoCore(
            per_joint(k1, n, "eso.k1"),
            per_joint(k2, n, "eso.k2"),
            per_joint(k3, n, "eso.k3"),
            substeps,
        )
        self._out = np.zeros(n)
        self._guard = SampleGuard(self.n)
        self._own_backend(model, backend)

    def _warm(self) -> None:
        c, snap = self.core, self.snapshot
        scratch = EsoCore(c.k1, c.k2, c.k3, c.substeps)
        scratch.step_compiled(np.zeros(self.n), snap.accel, 1e-3, snap.M, np.zeros(self.n))

    def reset(self, q: np.ndarray, qd: np.ndarray) -> None:
        self.snapshot.reset_memory()  # held friction: a new run has no memory
        self.core.reset(q, qd)

    def update_snapshot(self, snap: DynamicsSnapshot, dt: float) -> np.ndarray:
        if not self._guard.usable(snap, dt):
            return self._guard.nan()
        if self.backend == "numba":
            self.core.step_compiled(snap.q, snap.accel, dt, snap.M, self._out)
            return self._out
        return np.dot(snap.M, self.core.step(snap.q, snap.accel, dt), out=self._out)
