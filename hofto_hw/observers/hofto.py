"""High-order finite-time observer (HOFTO), eq. (17) of the paper, of any order n >= 1.

States per joint: z1 ≈ q, z2 ≈ qd, z3 ≈ x3 = M⁻¹·tau_ext, z4 ≈ x3', ..., z_{n+2} ≈ x3^(n-1);
the estimate is tau_ext_hat = M(q)·z3. With a(q, qd, tau) = M⁻¹·tau + F(q, qd) (eq. (4)) and
stage powers p_1..p_{n+2} (eq. (17): p_i = m_{i+1} = 1 + i·sigma), two gain conventions:

``eq17`` — every stage driven by e1 = q - z1, exactly as printed:
    z1' = z2 + L1·sig^p1(e1)
    z2' = a + z3 + L2·sig^p2(e1)
    z_i' = z_{i+1} + L_i·sig^p_i(e1)        (3 <= i <= n+1)
    z_{n+2}' = L_{n+2}·sig^p_{n+2}(e1)

``recursive`` — Levant's nested (recursive) differentiator, each stage driven by the
difference to the previous stage's output, the convention of the paper's Section IV gains:
    v1 = z2 - L1·sig^p1(z1 - q);            z1' = v1
    v2 = z3 - L2·sig^p2(z2 - v1);           z2' = a + v2
    v_i = z_{i+1} - L_i·sig^p_i(z_i - v_{i-1});   z_i' = v_i   (3 <= i <= n+1)
    z_{n+2}' = -L_{n+2}·sig^p_{n+2}(z_{n+2} - v_{n+1})
Putting the paper's numbers into eq17 literally gives an unstable linearisation
(s⁴ + 22.36 s³ + 22.10 s² + 30 s + 440 has roots with positive real part); in the recursive
form they are stable (see docs/observers.md).

sig^p(x) = |x|^p·sign(x); p = 0 is sign(), p = 1 is linear (Remark 7's ESO/STA cases).

Discretisation: one step per sample (``substeps`` = 1, the default) in predictor-corrector
order with Taylor terms, exact on polynomial signals (see :class:`HoftoCore` and
docs/observers.md for the measured comparison with forward Euler and substeps). With
``substeps`` > 1 the measured q is interpolated linearly between samples (first-order hold)
and the model acceleration a is held. No allocation in a step.

The arithmetic is :mod:`hofto_hw.observers.kernels`' (``hofto_step``), compiled (backend
``numba``) or its source run as Python (``python``); the numpy formulation of the equations
above is the reference in tests/hofto_hw/observers/reference.py.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from hofto_hw import jit
from hofto_hw.model.robot import RobotModel
from hofto_hw.model.snapshot import DynamicsSnapshot, Needs
from hofto_hw.observers import kernels
from hofto_hw.observers.base import SampleGuard, SnapshotUpdate

Form = Literal["eq17", "recursive"]


class HoftoCore:
    """The observer dynamics without the robot model, for ``joints`` independent channels.

    ``gains`` shape (n+2, joints), ``powers`` shape (n+2,). :meth:`step` takes the measured
    position y and the model acceleration a (both shape (joints,)) and advances dt seconds.

    ``discretisation``:
    - ``taylor`` (default): predict every state to the new sampling instant by its Taylor
      series in the states above it, z_i += sum_{j>=1} h^j/j!·z_{i+j} (plus the model
      acceleration's h and h²/2 terms), then correct with the output injection of the new
      sample (Livne and Levant's proper discretisation of differentiators, in
      predictor-corrector order). The discrete observer is then exact on polynomial signals.
    - ``euler``: classic forward Euler, injecting with the previous state (how eq. (5)'s ESO
      and the STA are discretised here, so Remark 7's equivalence holds sample by sample).
      It lags: on a unit double integrator with a ramp x3 of slope s its error settles at
      ~5·dt·s for n = 2, and it grows with time on a parabola.

    ``backend`` (``auto``, ``numba``, ``python``: see :mod:`hofto_hw.jit`) is
    the one :meth:`step` runs (``kernels.hofto_advance``, compiled at its first call); the
    observer updates the same record through its own kernel call.
    """

    def __init__(
        self,
        gains: np.ndarray,
        powers: np.ndarray,
        form: Form = "recursive",
        substeps: int = 1,
        discretisation: Literal["taylor", "euler"] = "taylor",
        backend: jit.Backend = "auto",
    ) -> None:
        gains = np.asarray(gains, dtype=float)
        powers = np.asarray(powers, dtype=float).reshape(-1)
        if gains.ndim != 2 or gains.shape[0] < 3:
            raise ValueError("gains must have shape (n+2, joints) with n >= 1")
        if powers.shape != (gains.shape[0],):
            raise ValueError(f"powers must have {gains.shape[0]} entries, got {powers.size}")
        if np.any(gains <= 0) or not np.all(np.isfinite(gains)):
            raise ValueError("gains must be finite and > 0")
        if np.any(powers < 0) or np.any(powers > 1):
            raise ValueError("powers must lie in [0, 1]")
        if form not in ("eq17", "recursive"):
            raise ValueError(f"form must be 'eq17' or 'recursive', got {form!r}")
        if discretisation not in ("taylor", "euler"):
            raise ValueError(f"discretisation must be 'taylor' or 'euler', got {discretisation!r}")
        if substeps < 1:
            raise ValueError("substeps must be >= 1")
        self.stages, self.joints = gains.shape
        self.order = self.stages - 2
        self.gains = gains.copy()
        self.form = form
        self.discretisation = discretisation
        self.substeps = int(substeps)
        s, j = self.stages, self.joints
        #: the state and parameters the kernels read and write, as one record (the observer
        #: and observers.bank pass it as one argument): z, -L, powers, the previous sample,
        #: the step terms (T, [h, a_h2], scratch: ``work``), substeps and flags
        #: (kernels.BANK_RECURSIVE | BANK_TAYLOR); the attributes are its fields
        f8 = np.float64
        self.record = np.zeros(
            1,
            jit.interned(np.dtype(
                [("z", f8, (s, j)), ("neg_gains", f8, (s, j)), ("powers", f8, (s,)),
                 ("prev", f8, (j,)), ("work", f8, (s + 3, s)), ("substeps", np.int64),
                 ("flags", np.int64)],
                align=True,
            )),
        )  # fmt: skip
        rec = self.record[0]
        self.z = rec["z"]
        self.powers = rec["powers"]
        self.powers[:] = powers
        #: the previous sample y (joints,)
        self.prev = rec["prev"]
        work = rec["work"]
        work[:s] = np.eye(s)
        work[s, 0] = -1.0  # h < 0: no step yet
        rec["substeps"] = self.substeps
        rec["flags"] = (kernels.BANK_RECURSIVE if form == "recursive" else 0) | (
            kernels.BANK_TAYLOR if discretisation == "taylor" else 0
        )
        self._neg_gains = rec["neg_gains"]
        np.negative(self.gains, out=self._neg_gains)
        self._work = work
        self._ints = int(rec["substeps"]), int(rec["flags"])
        self.backend = jit.resolve(backend)
        self._step = jit.compiled_or_python(kernels.hofto_advance, self.backend)

    def reset(self, y: np.ndarray, yd: np.ndarray | None = None) -> None:
        """z1 = y, z2 = yd (or 0), higher states 0."""
        self.z.fill(0.0)
        self.z[0] = y
        self.prev[:] = y
        if yd is not None:
            self.z[1] = yd

    def step(self, y: np.ndarray, a: np.ndarray, dt: float) -> np.ndarray:
        """Advance ``dt`` [s]; returns z3 (a view), the x3 estimate."""
        sub, flags = self._ints
        self._step(
            self.z, self._neg_gains, self.powers, self.prev, self._work, sub, flags, y, a, dt
        )
        return self.z[2]


class HoftoObserver(SnapshotUpdate):
    """HOFTO on a robot: tau_ext_hat = M(q)·z3 (eq. (17)); one ``kernels.hofto_update`` call
    per update (``backend``: see :mod:`hofto_hw.observers.base`)."""

    name = "hofto"
    needs = Needs.ACCEL | Needs.MASS

    def __init__(
        self,
        model: RobotModel,
        gains: np.ndarray,
        powers: np.ndarray,
        form: Form = "recursive",
        substeps: int = 1,
        discretisation: Literal["taylor", "euler"] = "taylor",
        backend: jit.Backend = "auto",
    ) -> None:
        gains = np.asarray(gains, dtype=float)
        if gains.ndim != 2 or gains.shape[1] != model.n:
            raise ValueError(f"gains must have shape (n+2, {model.n}), got {gains.shape}")
        self.model = model
        self.n = model.n
        self.core = HoftoCore(gains, powers, form, substeps, discretisation, backend)
        self.order = self.core.order
        self._out = np.zeros(self.n)
        self._guard = SampleGuard(self.n)
        self._own_backend(model, backend, kernels.hofto_update)

    def _warm(self) -> None:
        """Compile the kernel on a scratch copy of the record (the state is untouched)."""
        snap = self.snapshot
        kernels.hofto_update(
            self.core.record.copy(), np.zeros(self.n), snap.accel, 1e-3, snap.M, np.zeros(self.n)
        )

    def reset(self, q: np.ndarray, qd: np.ndarray) -> None:
        self.snapshot.reset_memory()  # held friction: a new run has no memory
        self.core.reset(q, qd)

    def update_snapshot(self, snap: DynamicsSnapshot, dt: float) -> np.ndarray:
        if not self._guard.usable(snap, dt):
            return self._guard.nan()
        self._kernel(self.core.record, snap.q, snap.accel, dt, snap.M, self._out)
        return self._out
