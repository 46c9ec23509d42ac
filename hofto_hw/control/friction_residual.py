"""The friction model's error, learned from contact-free motion, for the drag's estimate.

A tare taken at rest removes the estimate's bias at the pose where dragging starts, but not
the friction model's error: once a joint moves, the true friction differs from the model's
by dFc_j·s(qd_j) + dFv_j·qd_j (a few % of Coulomb and viscous friction), a term that switches
with the direction of motion. The estimate carries it as -dFc_j·s(qd_j) - dFv_j·qd_j, which
the drag cannot tell from a hand: mapped through (Jᵀ)⁺ it is a sideways force (ER3A sim,
3 kg, the README main job's pose: joints 1-3 carry +0.37, -0.28, -0.23 N·m, 1.4 N across an
x push, 7 mm/s off-axis).

While the arm moves with no hand on it (any mode but drag, no contact reported, no stop)
:meth:`FrictionResidual.learn` regresses the drag observer's estimate per joint on
x = (1, s(qd), qd), s = tanh(qd / v_s), as exponentially weighted sums (time constant
``time_constant`` of motion). :meth:`solve` (at drag entry) gives per joint the ridge
least-squares coefficients; :meth:`correction` is c_s·s(qd) + c_v·qd (the constant is the
tare's job), bounded by ``limit`` times the model's own friction at qd. With no motion seen
the correction is zero. Units: rad/s, N·m. Allocation-free per tick (solve included).

:meth:`FrictionResidual.learn` is the kernel :func:`hofto_hw.control.kernels.friction_learn`
(its one place; the tick's fused call compiles the same function): compiled for backend
``numba`` (``auto`` where numba works), its own source run by the interpreter for ``python``;
the feature s(qd) of :meth:`correction` is that kernel's own
(:func:`~hofto_hw.control.kernels.friction_feature`), and the bound's model friction is
FrictionParams.torque (the model's friction kernel).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from hofto_hw import jit
from hofto_hw.control.kernels import friction_features, friction_learn
from hofto_hw.jit import Backend
from hofto_hw.model.friction import FrictionParams


class FrictionResidual:
    """See the module docstring. ``friction``: the model's friction (its smooth sign's
    velocity and the bound); ``time_constant`` [s] of motion; ``min_speed`` [rad/s]: a tick
    is learned from only when some joint is faster; ``ridge``: the prior toward no error
    (in units of the features' mean square); ``limit``: |correction| <= limit · |f_model(qd)|;
    ``every``: one moving sample in this many is learned from (~12 µs each: friction needs no
    more than a few hundred samples a second, the tick keeps the rest).
    Public: ``coef`` (n, 3) [N·m, N·m, N·m·s/rad] after :meth:`solve`, ``seconds`` [s] of
    motion learned from."""

    def __init__(
        self,
        friction: FrictionParams,
        time_constant: float = 5.0,
        min_speed: float = 0.05,
        ridge: float = 0.01,
        limit: float = 0.25,
        every: int = 4,
        backend: Backend = "python",
        hot: Mapping[str, np.ndarray] | None = None,
    ) -> None:
        n = friction.coulomb.shape[0]
        self.friction = friction
        self.v_s = friction.smooth_velocity if friction.smooth_velocity > 0.0 else 0.02
        self.tau = float(time_constant)
        self.min_speed = float(min_speed)
        self.ridge = float(ridge)
        self.limit = float(limit)
        self.n = n
        #: the learned sums as one record (the tick's compiled call takes it as one argument):
        #: S, b and _st are its fields
        self.record = np.zeros(1, self.hot_fields(n)["record"]) if hot is None else hot["record"]
        self.S = self.record["S"][0]  # weighted mean of x·xᵀ per joint
        self.b = self.record["b"][0]  # weighted mean of x·r per joint
        self.coef = np.zeros((n, 3))
        self.every = max(1, int(every))
        self._s = np.zeros(n)
        self._f = np.zeros(n)
        self._scratch = friction.workspace()  # FrictionParams.torque's, for the bound
        self._st = self.record["st"][0]  # count, pending time [s], seconds learned [s]
        self.backend = jit.ready(backend, self._warm)
        #: True exactly when the compiled kernel runs (the tick's fused call reads it)
        self._use_kernel = self.backend == "numba"
        self._learn = jit.compiled_or_python(friction_learn, self.backend)
        self._features = jit.compiled_or_python(friction_features, self.backend)

    @staticmethod
    def hot_fields(n: int) -> dict[str, np.dtype]:
        """The learned sums (S, b, st) as one record, a field of a caller-owned record
        (``hot=``: the constructor takes it, zeroed, instead of allocating)."""
        rec = np.dtype([("S", np.float64, (n, 3, 3)), ("b", np.float64, (n, 3)),
                        ("st", np.float64, (3,))])  # fmt: skip
        return {"record": rec}

    @property
    def seconds(self) -> float:
        """[s] of motion learned from."""
        return float(self._st[2])

    def _warm(self) -> None:
        z = np.zeros(self.n)
        S, b, st = np.zeros_like(self.S), np.zeros_like(self.b), np.zeros(3)
        friction_learn(z, z, 0.001, self.v_s, self.tau, self.min_speed, self.every, S, b, st)
        friction_features(z, self.v_s, np.zeros(self.n))

    def reset(self) -> None:
        """Forget everything learned (another arm, a new payload)."""
        self.S.fill(0.0)
        self.b.fill(0.0)
        self.coef.fill(0.0)
        self._st.fill(0.0)

    def learn(self, qd: np.ndarray, tau_ext: np.ndarray, dt: float) -> bool:
        """One sample of contact-free motion: ``qd`` (n,) [rad/s], the estimate ``tau_ext``
        (n,) [N·m], ``dt`` [s]. Returns whether it counts (some joint above min_speed; one
        in ``every`` such samples is learned from, weighted by the time since the last)."""
        return self._learn(
            qd,
            tau_ext,
            dt,
            self.v_s,
            self.tau,
            self.min_speed,
            self.every,
            self.S,
            self.b,
            self._st,
        )

    def solve(self) -> np.ndarray:
        """The per-joint coefficients (n, 3) from what was learned: (S + ridge·D)·c = b with
        D = diag(0, 1, mean qd²) (the constant is free, the friction terms shrink toward 0
        when motion was scarce). Allocation-free (3 × 3 per joint by hand)."""
        S, b, c = self.S, self.b, self.coef
        for j in range(self.n):
            a00, a01, a02 = S[j, 0, 0], S[j, 0, 1], S[j, 0, 2]
            a11, a12, a22 = S[j, 1, 1], S[j, 1, 2], S[j, 2, 2]
            a00 += 1e-9
            a11 += self.ridge
            a22 += self.ridge * max(a22, 1e-3)
            b0, b1, b2 = b[j, 0], b[j, 1], b[j, 2]
            # symmetric 3 × 3 by cofactors
            c00 = a11 * a22 - a12 * a12
            c01 = a02 * a12 - a01 * a22
            c02 = a01 * a12 - a02 * a11
            det = a00 * c00 + a01 * c01 + a02 * c02
            if not (abs(det) > 1e-15 and math.isfinite(det)):
                c[j] = 0.0
                continue
            c11 = a00 * a22 - a02 * a02
            c12 = a01 * a02 - a00 * a12
            c22 = a00 * a11 - a01 * a01
            c[j, 0] = (c00 * b0 + c01 * b1 + c02 * b2) / det
            c[j, 1] = (c01 * b0 + c11 * b1 + c12 * b2) / det
            c[j, 2] = (c02 * b0 + c12 * b1 + c22 * b2) / det
        if not np.isfinite(c).all():
            c.fill(0.0)
        return c

    def correction(self, qd: np.ndarray, out: np.ndarray) -> np.ndarray:
        """The estimate's friction error at ``qd`` (n,) [rad/s], c_s·s(qd) + c_v·qd, bounded
        by ``limit``·|f_model(qd)|, into ``out`` (n,) [N·m]; subtract it from the estimate."""
        s = self._s
        self._features(qd, self.v_s, s)
        np.multiply(self.coef[:, 1], s, out=out)
        np.multiply(self.coef[:, 2], qd, out=s)
        out += s
        self.friction.torque(qd, self._f, self._scratch)
        np.abs(self._f, out=self._f)
        self._f *= self.limit
        np.minimum(out, self._f, out=out)
        np.negative(self._f, out=self._f)
        np.maximum(out, self._f, out=out)
        return out
