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
equivalence holds sample by sample. The arithmetic is :mod:`hofto_hw.observers.kernels`'
(``euler_step``; the numpy reference is in tests/hofto_hw/observers/reference.py).
"""

from __future__ import annotations

import numpy as np

from hofto_hw import jit
from hofto_hw.model.robot import RobotModel
from hofto_hw.model.snapshot import DynamicsSnapshot, Needs
from hofto_hw.observers import kernels
from hofto_hw.observers.base import SampleGuard, SnapshotUpdate, per_joint


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

    States z (3, joints) (``z1``, ``z2``, ``z3`` are row views), gains k (3, joints), the
    previous sample ``prev`` (joints,). :meth:`step` runs ``kernels.euler_step`` on
    ``backend`` (see :mod:`hofto_hw.jit`; compiled at its first call)."""

    def __init__(
        self,
        k1: np.ndarray,
        k2: np.ndarray,
        k3: np.ndarray,
        substeps: int = 1,
        backend: jit.Backend = "auto",
    ) -> None:
        self.k = np.vstack([np.asarray(k, dtype=float) for k in (k1, k2, k3)])
        self.k1, self.k2, self.k3 = self.k
        self.substeps = int(substeps)
        j = self.k1.shape[0]
        self.z = np.zeros((3, j))
        self.z1, self.z2, self.z3 = self.z
        self.prev = np.zeros(j)
        self.backend = jit.resolve(backend)
        self._step = jit.compiled_or_python(kernels.euler_step, self.backend)

    def reset(self, y: np.ndarray, yd: np.ndarray | None = None) -> None:
        self.z1[:] = y
        self.z2[:] = 0.0 if yd is None else yd
        self.z3.fill(0.0)
        self.prev[:] = y

    def step(self, y: np.ndarray, a: np.ndarray, dt: float) -> np.ndarray:
        """Advance ``dt`` [s]; returns z3 (a view), the x3 estimate."""
        self._step(self.z, self.k, y, self.prev, a, dt / self.substeps, self.substeps, False)
        return self.z3


class EsoObserver(SnapshotUpdate):
    """ESO on a robot: tau_ext_hat = M(q)·z3; one ``kernels.euler_update`` call per update
    (``backend``: see :mod:`hofto_hw.observers.base`)."""

    name = "eso"
    needs = Needs.ACCEL | Needs.MASS

    def __init__(
        self,
        model: RobotModel,
        k1: np.ndarray,
        k2: np.ndarray,
        k3: np.ndarray,
        substeps: int = 1,
        backend: jit.Backend = "auto",
    ) -> None:
        n = model.n
        self.model = model
        self.n = n
        self.core = EsoCore(
            per_joint(k1, n, "eso.k1"),
            per_joint(k2, n, "eso.k2"),
            per_joint(k3, n, "eso.k3"),
            substeps,
            backend,
        )
        self._out = np.zeros(n)
        self._guard = SampleGuard(self.n)
        self._own_backend(model, backend, kernels.euler_update)

    def _warm(self) -> None:
        c, snap, z = self.core, self.snapshot, np.zeros(self.n)
        kernels.euler_update(c.z.copy(), c.k, z, z.copy(), snap.accel, 1e-3, 1, False, snap.M, z)

    def reset(self, q: np.ndarray, qd: np.ndarray) -> None:
        self.snapshot.reset_memory()  # held friction: a new run has no memory
        self.core.reset(q, qd)

    def update_snapshot(self, snap: DynamicsSnapshot, dt: float) -> np.ndarray:
        if not self._guard.usable(snap, dt):
            return self._guard.nan()
        c, h = self.core, dt / self.core.substeps
        self._kernel(c.z, c.k, snap.q, c.prev, snap.accel, h, c.substeps, False, snap.M, self._out)
        return self._out
