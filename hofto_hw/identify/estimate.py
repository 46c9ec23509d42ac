"""Least-squares estimation of the base parameters, eq. (15): T = H·mu.

The stacked base regressor is never held in memory: every chunk of samples is folded into a
per-joint triangular factor R_j of [H_j | T_j] (incremental QR). Ordinary least squares
stacks all R_j; weighted least squares scales each R_j by 1/sigma_j (the joint's OLS residual
std). Memory is O(n·p²) whatever the recording length, and per-joint residual norms are exact.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from hofto_hw.errors import UserError
from hofto_hw.identify.base_params import BaseParameters
from hofto_hw.identify.regressor import Regressor, held_sign_series
from hofto_hw.identify.threads import one_blas_thread

MAX_CONDITION = 1e6  # above this the data do not determine every base parameter
# (real UR10e excitation runs: ~80; optimized simulated ER3A runs: ~100)


class Accumulator:
    """Folds samples into per-joint R factors of [H_b | tau] (each (p+1, p+1))."""

    def __init__(self, regressor: Regressor, base: BaseParameters, chunk: int = 2000) -> None:
        self.regressor = regressor
        self.base = base
        self.n = regressor.n
        self.p = base.p
        self.chunk = chunk
        self.R = np.zeros((self.n, self.p + 1, self.p + 1))
        self.samples = 0
        self.tau_sq = np.zeros(self.n)
        self._H = np.zeros((chunk * self.n, regressor.n_std))

    @one_blas_thread
    def add(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, tau: np.ndarray) -> None:
        """Add N samples: q [rad], qd [rad/s], qdd [rad/s²], tau [N·m], each (N, n)."""
        tau = np.asarray(tau, dtype=float)
        if tau.shape != np.shape(q):
            raise UserError(f"identify: tau has shape {tau.shape}, q has {np.shape(q)}")
        reg = self.regressor
        held = None
        if reg.held_velocity is not None:  # the memory runs over the whole recording
            held = held_sign_series(np.asarray(qd, dtype=float), reg.held_velocity)
        for start in range(0, tau.shape[0], self.chunk):
            sl = slice(start, start + self.chunk)
            m = tau[sl].shape[0]
            H = reg.stack(
                q[sl],
                qd[sl],
                qdd[sl],
                out=self._H[: m * self.n],
                held=None if held is None else held[sl],
            )
            Hb = H[:, self.base.columns].reshape(m, self.n, self.p)
            for j in range(self.n):
                A = np.empty((self.p + 1 + m, self.p + 1))
                A[: self.p + 1] = self.R[j]
                A[self.p + 1 :, : self.p] = Hb[:, j, :]
                A[self.p + 1 :, self.p] = tau[sl, j]
                r = scipy.linalg.qr(A, mode="r", overwrite_a=True, check_finite=False)[0]
                k = min(r.shape[0], self.p + 1)
                self.R[j] = 0.0
                self.R[j, :k] = r[:k]
            self.tau_sq += np.sum(tau[sl] ** 2, axis=0)
            self.samples += m

    def combined(self, weights: np.ndarray | None = None) -> np.ndarray:
        """R factor (p+1, p+1) of the (weighted) stacked system; weights (n,) scale joints."""
        w = np.ones(self.n) if weights is None else np.asarray(weights, dtype=float)
        A = (self.R * w[:, None, None]).reshape(-1, self.p + 1)
        return scipy.linalg.qr(A, mode="r", check_finite=False)[0][: self.p + 1]

    def joint_residuals(self, mu: np.ndarray) -> np.ndarray:
        """||tau_j - H_j·mu||_2 per joint, shape (n,) [N·m]."""
        x = np.append(mu, -1.0)
        return np.linalg.norm(self.R @ x, axis=1)


@dataclass
class Estimate:
    """Result of a least-squares fit.

    mu, std (p,): base parameters and their standard deviations; rmse, relative_rmse_percent,
    residual_std (n,) on the fitting data; condition_number of the (unweighted) H_b.
    """

    method: str
    mu: np.ndarray
    std: np.ndarray
    rmse: np.ndarray
    relative_rmse_percent: np.ndarray
    residual_std: np.ndarray
    condition_number: float
    samples: int

    @property
    def relative_std_percent(self) -> np.ndarray:
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.mu != 0.0, 100.0 * self.std / np.abs(self.mu), np.inf)


def _solve(R: np.ndarray, p: int) -> tuple[np.ndarray, np.ndarray]:
    R11 = R[:p, :p]
    mu = scipy.linalg.solve_triangular(R11, R[:p, p])
    Rinv = scipy.linalg.solve_triangular(R11, np.eye(p))
    return mu, Rinv


def check_excitation(acc: Accumulator) -> float:
    """Condition number of H_b; UserError if the data are too short or do not excite a
    base parameter (naming the worst-determined one)."""
    p = acc.p
    if acc.samples < 2 * p:
        raise UserError(
            f"identify: {acc.samples} samples are too few for {p} base parameters "
            f"(need at least {2 * p}; a real fit wants thousands)"
        )
    R11 = acc.combined()[:p, :p]
    scale = np.linalg.norm(R11, axis=0)
    if np.any(scale == 0.0):
        i = int(np.argmin(scale))
        raise UserError(
            f"identify: the data do not excite base parameter {acc.base.names[i]} "
            "(its regressor column is zero: is the arm moving?)"
        )
    # Raw singular values: a joint that only moves by noise leaves columns that are tiny in SI
    # units (column scaling would hide them); the smallest singular vector names the culprit.
    _, s, vt = np.linalg.svd(R11)
    cond = float(s[0] / s[-1])
    if cond > MAX_CONDITION:
        worst = acc.base.names[int(np.argmax(np.abs(vt[-1])))]
        raise UserError(
            f"identify: the data are rank deficient (condition number {cond:.3g}); base "
            f"parameter {worst} is not determined: use a richer excitation trajectory"
        )
    return cond


@one_blas_thread
def least_squares(acc: Accumulator, weighted: bool = False) -> Estimate:
    """OLS (or WLS with per-joint weights 1/sigma_j from a first OLS pass)."""
    cond = check_excitation(acc)
    n, p, N = acc.n, acc.p, acc.samples
    R = acc.combined()
    mu, Rinv = _solve(R, p)
    res = acc.joint_residuals(mu)
    dof_j = max(N - p / n, 1.0)
    sigma_j = res / np.sqrt(dof_j)
    if weighted:
        w = 1.0 / np.maximum(sigma_j, 1e-9 * max(sigma_j.max(), 1e-12))
        R = acc.combined(w)
        mu, Rinv = _solve(R, p)
        res = acc.joint_residuals(mu)
        sigma_j = res / np.sqrt(dof_j)
        cov = Rinv @ Rinv.T  # weights already whiten the residuals
        # Rescale by the weighted residual variance (close to 1 when the weights are right).
        wres = np.sum((res * w) ** 2) / max(N * n - p, 1)
        cov *= wres
    else:
        s2 = np.sum(res**2) / max(N * n - p, 1)
        cov = s2 * (Rinv @ Rinv.T)
    return Estimate(
        method="wls" if weighted else "ols",
        mu=mu,
        std=np.sqrt(np.maximum(np.diag(cov), 0.0)),
        rmse=res / np.sqrt(N),
        relative_rmse_percent=100.0 * res / np.sqrt(np.maximum(acc.tau_sq, 1e-300)),
        residual_std=sigma_j,
        condition_number=cond,
        samples=N,
    )
