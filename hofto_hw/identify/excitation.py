"""Optimized excitation trajectories: a finite Fourier series per joint (Swevers et al., 1997).

    q_j(t)   = q0_j + Σ_l  a_jl/(ω·l)·sin(ω·l·t) − b_jl/(ω·l)·cos(ω·l·t),   l = 1..L
    qd_j(t)  = Σ_l a_jl·cos(ω·l·t) + b_jl·sin(ω·l·t)
    qdd_j(t) = Σ_l ω·l·(−a_jl·sin(ω·l·t) + b_jl·cos(ω·l·t)),      ω = 2π / period

The series is periodic; it starts and ends at rest because a_jL and b_jL are fixed by
Σ_l a_jl = 0 (qd(0) = 0) and Σ_l l·b_jl = 0 (qdd(0) = 0). q, qd, qdd are linear in the free
coefficients, so position, velocity and acceleration limits are linear constraints; torque
limits (nominal model) are nonlinear ones. SLSQP minimizes the condition number of the stacked
base regressor at ``n_points`` instants of one period.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.optimize

from hofto_hw.errors import UserError
from hofto_hw.identify.base_params import BaseParameters
from hofto_hw.identify.regressor import Regressor
from hofto_hw.identify.threads import one_blas_thread


@dataclass
class FourierTrajectory:
    """One period of a Fourier excitation: period [s], q0 (n,) [rad], a, b (n, L) [rad/s]."""

    period: float
    q0: np.ndarray
    a: np.ndarray
    b: np.ndarray

    @property
    def omega(self) -> float:
        return 2.0 * np.pi / self.period

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q [rad], qd [rad/s], qdd [rad/s²] at times t (N,) [s], each (N, n)."""
        t = np.asarray(t, dtype=float)
        L = self.a.shape[1]
        wl = self.omega * np.arange(1, L + 1)
        s, c = np.sin(np.outer(t, wl)), np.cos(np.outer(t, wl))  # (N, L)
        q = self.q0 + s @ (self.a / wl).T - c @ (self.b / wl).T
        qd = c @ self.a.T + s @ self.b.T
        qdd = -s @ (self.a * wl).T + c @ (self.b * wl).T
        return q, qd, qdd


@dataclass
class ExcitationLimits:
    """Per-joint bounds, arrays (n,): position [rad], velocity [rad/s], acceleration
    [rad/s²], torque [N·m] (inf = unconstrained)."""

    position_lower: np.ndarray
    position_upper: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    torque: np.ndarray


def _basis(period: float, L: int, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Matrices mapping one joint's free vector [q0, a_1..a_{L-1}, b_1..b_{L-1}] to q, qd,
    qdd at times t; each (N, 2L-1)."""
    w = 2.0 * np.pi / period
    l = np.arange(1, L + 1)
    wl = w * l
    s, c = np.sin(np.outer(t, wl)), np.cos(np.outer(t, wl))
    # a_L = -Σ a_l ; b_L = -Σ l·b_l / L
    Pa = np.vstack([np.eye(L - 1), -np.ones((1, L - 1))])  # (L, L-1)
    Pb = np.vstack([np.eye(L - 1), -l[: L - 1][None, :] / L])
    one = np.ones((t.size, 1))
    Bq = np.hstack([one, (s / wl) @ Pa, -(c / wl) @ Pb])
    Bqd = np.hstack([0 * one, c @ Pa, s @ Pb])
    Bqdd = np.hstack([0 * one, -(s * wl) @ Pa, (c * wl) @ Pb])
    return Bq, Bqd, Bqdd


def trajectory_from_vector(x: np.ndarray, n: int, L: int, period: float) -> FourierTrajectory:
    """Unpack the optimizer's vector (n·(2L−1),) into a :class:`FourierTrajectory`."""
    X = x.reshape(n, 2 * L - 1)
    a = np.zeros((n, L))
    b = np.zeros((n, L))
    a[:, : L - 1] = X[:, 1:L]
    b[:, : L - 1] = X[:, L:]
    a[:, L - 1] = -a[:, : L - 1].sum(axis=1)
    b[:, L - 1] = -(np.arange(1, L) * b[:, : L - 1]).sum(axis=1) / L
    return FourierTrajectory(period, X[:, 0].copy(), a, b)


@one_blas_thread
def design_excitation(
    regressor: Regressor,
    base: BaseParameters,
    limits: ExcitationLimits,
    harmonics: int = 5,
    period: float = 10.0,
    n_points: int = 100,
    max_iter: int = 100,
    seed: int = 0,
    nominal: np.ndarray | None = None,
    progress: Callable[[int, float], None] | None = None,
) -> tuple[FourierTrajectory, float]:
    """Optimize a Fourier excitation; returns the trajectory and its condition number.

    ``nominal`` (14·n,): standard parameters used for the torque limits (None = no torque
    constraint). ``progress(iteration, cond)`` is called after each SLSQP iteration.
    """
    n, L = regressor.n, harmonics
    if L < 2:
        raise UserError("excite: --harmonics must be at least 2 (rest at both ends)")
    lo, hi = limits.position_lower, limits.position_upper
    if np.any(~np.isfinite(lo)) or np.any(~np.isfinite(hi)) or np.any(hi <= lo):
        raise UserError("excite: finite position limits with lower < upper are needed per joint")
    t_opt = np.linspace(0.0, period, n_points, endpoint=False)
    t_lim = np.linspace(0.0, period, 8 * n_points, endpoint=False)
    Bq, Bqd, Bqdd = _basis(period, L, t_lim)
    m = 2 * L - 1
    # Linear constraints per joint: lo <= Bq x <= hi, |Bqd x| <= v, |Bqdd x| <= acc.
    rows, ub = [], []
    for j in range(n):
        for B, low, up in (
            (Bq, lo[j], hi[j]),
            (Bqd, -limits.velocity[j], limits.velocity[j]),
            (Bqdd, -limits.acceleration[j], limits.acceleration[j]),
        ):
            if not np.isfinite(up):
                continue
            A = np.zeros((B.shape[0], n * m))
            A[:, j * m : (j + 1) * m] = B
            rows += [A, -A]
            ub += [np.full(B.shape[0], up), np.full(B.shape[0], -low)]
    A_lin, b_lin = np.vstack(rows), np.concatenate(ub)
    cols = base.columns

    def regress(x: np.ndarray) -> np.ndarray:
        traj = trajectory_from_vector(x, n, L, period)
        return regressor.stack(*traj.evaluate(t_opt))

    def cost(x: np.ndarray) -> float:
        return float(np.log10(np.linalg.cond(regress(x)[:, cols])))

    constraints: list[dict] = [
        {"type": "ineq", "fun": lambda x: b_lin - A_lin @ x, "jac": lambda x: -A_lin}
    ]
    if nominal is not None and np.any(np.isfinite(limits.torque)):
        tmax = np.where(np.isfinite(limits.torque), limits.torque, 1e12)

        def torque_margin(x: np.ndarray) -> np.ndarray:
            tau = (regress(x) @ nominal).reshape(-1, n)
            return (tmax - np.abs(tau)).ravel()

        constraints.append({"type": "ineq", "fun": torque_margin})

    x0 = _initial_guess(n, L, lo, hi, A_lin, b_lin, np.random.default_rng(seed))
    it = [0]

    def callback(x: np.ndarray) -> None:
        it[0] += 1
        if progress is not None:
            progress(it[0], 10 ** cost(x))

    res = scipy.optimize.minimize(
        cost,
        x0,
        method="SLSQP",
        constraints=constraints,
        options={"maxiter": max_iter, "ftol": 1e-6},
        callback=callback,
    )
    x = res.x if np.all(A_lin @ res.x <= b_lin + 1e-6) else x0
    traj = trajectory_from_vector(x, n, L, period)
    return traj, 10 ** cost(x)


def _initial_guess(
    n: int,
    L: int,
    lo: np.ndarray,
    hi: np.ndarray,
    A: np.ndarray,
    b: np.ndarray,
    rng: np.random.Generator,
) -> np.ndarray:
    """Random coefficients centred in the position range, shrunk until all limits hold."""
    m = 2 * L - 1
    X = np.zeros((n, m))
    X[:, 0] = 0.5 * (lo + hi)
    X[:, 1:] = rng.normal(0.0, 1.0, (n, m - 1)) / np.tile(np.arange(1, L), 2)
    x = X.ravel()
    centre = x.copy()
    centre[np.arange(n * m) % m != 0] = 0.0
    for _ in range(200):
        if np.all(A @ x <= b):
            return x
        x = centre + 0.8 * (x - centre)
    raise UserError("excite: the limits leave no room for motion (check position limits)")
