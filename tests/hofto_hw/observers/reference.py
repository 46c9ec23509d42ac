"""The observers written as numpy array operations: the reference the package's kernels
(hofto_hw/observers/kernels.py, compiled or run as Python) are checked against.

Each class here computes what its namesake in hofto_hw/observers computes, from the paper's
equations as vector operations over the joints, with none of the kernels' formulation
(per-joint loops, one log2 shared by the stages, record layouts): two
independent writings of each formula, so that an agreement test can fail. They take the same
constructor arguments (without ``backend``) and have ``reset(q, qd)``, ``update(q, qd, tau,
dt)`` and ``update_snapshot(snap, dt)``; they are not used by the package.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from hofto_hw.model.robot import RobotModel
from hofto_hw.model.snapshot import DynamicsSnapshot, Needs
from hofto_hw.observers.base import SampleGuard, SnapshotUpdate, per_joint


def sigma_powers(order: int, sigma: float) -> np.ndarray:
    """Stage powers 1 + i·sigma (i = 1..n+2) of eq. (17), shape (n+2,) (the package's are
    ``HoftoConfig.stage_powers()``)."""
    assert -1.0 / (order + 2) < sigma < 0.0
    return 1.0 + sigma * np.arange(1, order + 3, dtype=float)


class LinearHold:
    """First-order hold between two samples: over ``substeps`` substeps, :meth:`next` walks
    linearly from the previous sample to the new one (the k-th call returns
    y_prev + k·(y - y_prev)/substeps)."""

    def __init__(self, joints: int) -> None:
        self.prev = np.zeros(joints)
        self._cur = np.zeros(joints)
        self._step = np.zeros(joints)

    def reset(self, y: np.ndarray) -> None:
        np.copyto(self.prev, y)

    def begin(self, y: np.ndarray, substeps: int) -> None:
        np.subtract(y, self.prev, out=self._step)
        np.divide(self._step, substeps, out=self._step)
        np.copyto(self._cur, self.prev)

    def next(self) -> np.ndarray:
        np.add(self._cur, self._step, out=self._cur)
        return self._cur

    def end(self, y: np.ndarray) -> None:
        np.copyto(self.prev, y)


class HoftoCore:
    """hofto_hw.observers.hofto.HoftoCore as numpy operations: ``step(y, a, dt) -> z3``."""

    def __init__(
        self,
        gains: np.ndarray,
        powers: np.ndarray,
        form: str = "recursive",
        substeps: int = 1,
        discretisation: Literal["taylor", "euler"] = "taylor",
    ) -> None:
        self.gains = np.asarray(gains, dtype=float).copy()
        self.powers = np.asarray(powers, dtype=float).reshape(-1).copy()
        self.stages, self.joints = self.gains.shape
        self.form = form
        self.discretisation = discretisation
        self.substeps = int(substeps)
        s, j = self.stages, self.joints
        self.z = np.zeros((s, j))
        self._inj = np.zeros((s, j))
        self._neg_gains = -self.gains
        self._pow_col = self.powers.reshape(s, 1).copy()
        self._e, self._abs, self._d, self._t, self._prev = (np.zeros(j) for _ in range(5))
        self._hold = LinearHold(j)
        self._T = np.eye(s)
        self._h = -1.0
        self._a_h2 = 0.0

    def reset(self, y: np.ndarray, yd: np.ndarray | None = None) -> None:
        self.z.fill(0.0)
        self.z[0] = y
        self._hold.reset(y)
        if yd is not None:
            self.z[1] = yd

    def step(self, y: np.ndarray, a: np.ndarray, dt: float) -> np.ndarray:
        h = dt / self.substeps
        if h != self._h:
            self._set_step(h)
        self._hold.begin(y, self.substeps)
        for _ in range(self.substeps):
            self._substep(y if self.substeps == 1 else self._hold.next(), a, h)
        self._hold.end(y)
        return self.z[2]

    def _set_step(self, h: float) -> None:
        """T[i, i+j] = h^j/j! (Taylor) or I + h·shift (Euler)."""
        s = self.stages
        T = np.eye(s)
        terms = s if self.discretisation == "taylor" else 2
        coef = 1.0
        for j in range(1, terms):
            coef *= h / j
            T += coef * np.eye(s, k=j)
        self._T = T
        self._a_h2 = 0.5 * h * h if self.discretisation == "taylor" else 0.0
        self._h = h

    def _injection(self, y: np.ndarray) -> None:
        inj = self._inj
        if self.form == "eq17":  # every stage driven by e1 = y - z1: + L_i·sig^p_i(e1)
            e = self._e
            np.subtract(y, self.z[0], out=e)
            np.abs(e, out=self._abs)
            np.power(self._abs, self._pow_col, out=inj)
            np.copysign(inj, e, out=inj)
            for i in range(self.stages):
                if self.powers[i] == 0.0:
                    np.sign(e, out=inj[i])  # sig^0 = sign, with sig^0(0) = 0
            np.multiply(inj, self.gains, out=inj)
            return
        # recursive: stage i driven by z_i - v_{i-1}, v_i = z_{i+1} + inj_i, v_{-1} = y
        d, t, prev = self._d, self._t, self._prev
        np.copyto(prev, y)
        for i in range(self.stages):
            p = float(self.powers[i])
            np.subtract(self.z[i], prev, out=d)
            if p == 0.0:
                np.sign(d, out=t)
            else:
                np.abs(d, out=t)
                np.power(t, p, out=t)
                np.copysign(t, d, out=t)
            np.multiply(t, self._neg_gains[i], out=self._inj[i])
            if i + 1 < self.stages:
                np.add(self.z[i + 1], self._inj[i], out=prev)

    def _substep(self, y: np.ndarray, a: np.ndarray, h: float) -> None:
        z, inj = self.z, self._inj
        if self.discretisation == "euler":  # inject with the state of the previous instant
            self._injection(y)
            z[:] = self._T @ z + inj * h
            z[1] += a * h
            return
        # taylor: predict the chain to this instant (model acceleration included), then
        # correct it with the sample of this instant
        tz = self._T @ z
        tz[1] += a * h
        tz[0] += a * self._a_h2
        z[:] = tz
        self._injection(y)
        z += inj * h


class EsoCore:
    """hofto_hw.observers.eso.EsoCore as numpy operations: explicit Euler of eq. (5)."""

    def __init__(self, k1: np.ndarray, k2: np.ndarray, k3: np.ndarray, substeps: int = 1) -> None:
        self.k = np.vstack([np.asarray(k, dtype=float) for k in (k1, k2, k3)])
        self.substeps = int(substeps)
        self.z = np.zeros((3, self.k.shape[1]))
        self._hold = LinearHold(self.k.shape[1])

    def reset(self, y: np.ndarray, yd: np.ndarray | None = None) -> None:
        self.z[0] = y
        self.z[1] = 0.0 if yd is None else yd
        self.z[2] = 0.0
        self._hold.reset(y)

    def step(self, y: np.ndarray, a: np.ndarray, dt: float) -> np.ndarray:
        h = dt / self.substeps
        z, (k1, k2, k3) = self.z, self.k
        self._hold.begin(y, self.substeps)
        for _ in range(self.substeps):
            e = self._hold.next() - z[0]
            # every derivative from the old state (explicit Euler), then all states advance
            d1, d2, d3 = k1 * e + z[1], k2 * e + z[2] + a, k3 * e
            z[0] += d1 * h
            z[1] += d2 * h
            z[2] += d3 * h
        self._hold.end(y)
        return z[2]


class _Observer(SnapshotUpdate):
    """A reference observer on a robot: its own snapshot (model terms, numpy)."""

    def _setup(self, model: RobotModel) -> None:
        self.model = model
        self.n = model.n
        self.backend = "reference"
        self._guard = SampleGuard(self.n)
        self._own_snapshot(model, "python")

    def update_snapshot(self, snap: DynamicsSnapshot, dt: float) -> np.ndarray:
        if not self._guard.usable(snap, dt):
            return self._guard.nan()
        return self._step(snap, dt)


class HoftoObserver(_Observer):
    name = "hofto"
    needs = Needs.ACCEL | Needs.MASS

    def __init__(self, model, gains, powers, form="recursive", substeps=1, discretisation="taylor"):
        self.core = HoftoCore(gains, powers, form, substeps, discretisation)
        self._setup(model)

    def reset(self, q: np.ndarray, qd: np.ndarray) -> None:
        self.snapshot.reset_memory()
        self.core.reset(q, qd)

    def _step(self, snap: DynamicsSnapshot, dt: float) -> np.ndarray:
        return snap.M @ self.core.step(snap.q, snap.accel, dt)


class EsoObserver(_Observer):
    name = "eso"
    needs = Needs.ACCEL | Needs.MASS

    def __init__(self, model, k1, k2, k3, substeps=1):
        n = model.n
        ks = (per_joint(k, n, f"eso.k{i + 1}") for i, k in enumerate((k1, k2, k3)))
        self.core = EsoCore(*ks, substeps)
        self._setup(model)

    def reset(self, q: np.ndarray, qd: np.ndarray) -> None:
        self.snapshot.reset_memory()
        self.core.reset(q, qd)

    def _step(self, snap: DynamicsSnapshot, dt: float) -> np.ndarray:
        return snap.M @ self.core.step(snap.q, snap.accel, dt)


class StaObserver(_Observer):
    """Remark 7's super-twisting observer, explicit Euler (written on its own, not through
    HoftoCore)."""

    name = "sta"
    needs = Needs.ACCEL | Needs.MASS

    def __init__(self, model, l1, l2, l3, substeps=1):
        n = model.n
        self.gains = np.vstack([per_joint(v, n, "sta") for v in (l1, l2, l3)])
        self.substeps = int(substeps)
        self.z = np.zeros((3, n))
        self._hold = LinearHold(n)
        self._setup(model)

    def reset(self, q: np.ndarray, qd: np.ndarray) -> None:
        self.snapshot.reset_memory()
        self.z[0], self.z[1], self.z[2] = q, qd, 0.0
        self._hold.reset(q)

    def _step(self, snap: DynamicsSnapshot, dt: float) -> np.ndarray:
        h = dt / self.substeps
        z, (l1, l2, l3) = self.z, self.gains
        self._hold.begin(snap.q, self.substeps)
        for _ in range(self.substeps):
            e = self._hold.next() - z[0]
            root = np.copysign(np.sqrt(np.abs(e)), e)  # |e|^(1/2)·sign(e)
            d1, d2, d3 = l1 * root + z[1], l2 * root + z[2] + snap.accel, l3 * np.sign(e)
            z[0] += d1 * h
            z[1] += d2 * h
            z[2] += d3 * h
        self._hold.end(snap.q)
        return snap.M @ z[2]


class MomentumObserver(_Observer):
    """r = K_O·(M·qd - p0 - integral), integral += (tau - f - g + Cᵀ·qd + r)·dt (forward
    Euler with the previous residual)."""

    name = "momentum"
    needs = Needs.MASS | Needs.GRAVITY | Needs.CORIOLIS_T | Needs.FRICTION

    def __init__(self, model, gain):
        self.gain = per_joint(gain, model.n, "momentum.gain")
        self.p0, self.integral, self.r = (np.zeros(model.n) for _ in range(3))
        self._reset_data = model.create_data()
        self._setup(model)

    def reset(self, q: np.ndarray, qd: np.ndarray) -> None:
        self.snapshot.reset_memory()
        self.p0[:] = self._reset_data.mass_matrix(q) @ qd
        self.integral[:] = 0.0
        self.r[:] = 0.0

    def _step(self, snap: DynamicsSnapshot, dt: float) -> np.ndarray:
        self.integral += (snap.tau - snap.f - snap.g + snap.ct_qd + self.r) * dt
        self.r[:] = self.gain * (snap.M @ snap.qd - self.p0 - self.integral)
        return self.r


class DobObserver(_Observer):
    """w += (1 - exp(-g·dt))·(g·Jn·qd + tau - nle - f - w); tau_ext_hat = g·Jn·qd - w."""

    name = "dob"
    needs = Needs.NLE | Needs.FRICTION

    def __init__(self, model, cutoff, nominal_inertia=None):
        self.cutoff = per_joint(cutoff, model.n, "dob.cutoff")
        if nominal_inertia is None:
            nominal_inertia = np.diag(model.create_data().mass_matrix(model.home)).copy()
        self.gj = self.cutoff * per_joint(nominal_inertia, model.n, "dob.nominal_inertia")
        self.w = np.zeros(model.n)
        self._setup(model)

    def reset(self, q: np.ndarray, qd: np.ndarray) -> None:
        self.snapshot.reset_memory()
        self.w[:] = self.gj * qd

    def _step(self, snap: DynamicsSnapshot, dt: float) -> np.ndarray:
        alpha = -np.expm1(-self.cutoff * dt)
        gq = self.gj * snap.qd
        self.w += alpha * (gq + snap.tau - snap.nle - snap.f - self.w)
        return gq - self.w


#: product observer class name -> its reference class
REFERENCE = {
    cls.__name__: cls
    for cls in (HoftoObserver, EsoObserver, StaObserver, MomentumObserver, DobObserver)
}
