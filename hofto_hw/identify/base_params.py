"""Base parameters (eq. (14)): the identifiable combinations of the standard parameters.

Numerical method of Gautier (1990): stack H_s over random (q, qd, qdd), find the rank with a
column-pivoted QR, then walk the columns in their standard order and keep each column that
is independent of the ones kept before it. With H_s = [H_b, H_d] (kept / dropped columns)
and H_d = H_b·K_d, the base parameters are mu = theta_b + K_d·theta_d = K·theta_s, so
H_s·theta_s = H_b·mu. ``K`` (p, s) is the linear map stored in the parameters file.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from hofto_hw.errors import ModelError
from hofto_hw.identify.regressor import Regressor, standard_names
from hofto_hw.identify.threads import one_blas_thread

COEFF_ZERO = 1e-9  # |K| entries below this are rounding noise of the QR


@dataclass(frozen=True)
class BaseParameters:
    """The base-parameter definition.

    - ``columns`` (p,): indices of the standard parameters kept (H_b = H_s[:, columns]);
    - ``K`` (p, s): mu = K @ theta_s;
    - ``names`` (p,): name of the kept standard parameter each base parameter is built on;
    - ``standard_names`` (s,).
    """

    columns: np.ndarray
    K: np.ndarray
    names: list[str]
    standard_names: list[str]

    @property
    def p(self) -> int:
        """Number of base parameters."""
        return int(self.columns.size)

    def from_standard(self, theta: np.ndarray) -> np.ndarray:
        """mu = K·theta_s, shape (p,)."""
        return self.K @ theta

    def to_standard(self, mu: np.ndarray, prior: np.ndarray) -> np.ndarray:
        """A standard set that reproduces ``mu`` exactly: the dropped parameters keep their
        ``prior`` values (e.g. the URDF's), the kept ones absorb the rest. Shape (s,)."""
        theta = np.array(prior, dtype=float)
        theta[self.columns] = 0.0
        theta[self.columns] = mu - self.K @ theta
        return theta

    def expressions(self) -> list[list[tuple[str, float]]]:
        """Per base parameter, the (standard name, coefficient) pairs it sums."""
        out = []
        for row in self.K:
            nz = np.flatnonzero(row)
            out.append([(self.standard_names[i], float(row[i])) for i in nz])
        return out


def random_samples(
    n: int, n_samples: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random q [rad] in [-pi, pi], qd [rad/s] and qdd [rad/s²] in [-2, 2]; each (N, n)."""
    q = rng.uniform(-np.pi, np.pi, (n_samples, n))
    qd = rng.uniform(-2.0, 2.0, (n_samples, n))
    qdd = rng.uniform(-2.0, 2.0, (n_samples, n))
    return q, qd, qdd


@one_blas_thread
def find_base_parameters(
    regressor: Regressor,
    joint_names: list[str],
    n_samples: int = 120,
    seed: int = 0,
    rtol: float = 1e-9,
) -> BaseParameters:
    """Base parameters of the arm behind ``regressor`` from ``n_samples`` random samples.

    Columns are scaled to unit norm first so that the rank test does not depend on units.
    """
    rng = np.random.default_rng(seed)
    q, qd, qdd = random_samples(regressor.n, n_samples, rng)
    held = None
    if regressor.held_velocity is not None:
        # The held columns only live inside the velocity band: put a third of the samples
        # there, with a random held sign.
        k = n_samples // 3
        qd[-k:] *= 0.5 * regressor.held_velocity / 2.0
        held = np.sign(rng.uniform(-1.0, 1.0, qd.shape))
    W = regressor.stack(q, qd, qdd, held=held)
    norms = np.linalg.norm(W, axis=0)
    nonzero = norms > rtol * norms.max()
    Ws = np.where(nonzero, W / np.where(nonzero, norms, 1.0), 0.0)
    R = scipy.linalg.qr(Ws, mode="r", pivoting=True)[0]
    diag = np.abs(np.diag(R))
    rank = int(np.sum(diag > rtol * diag[0] * max(Ws.shape)))

    # Sequential selection in standard order (Gautier): keep a column when it raises the rank.
    R_seq = scipy.linalg.qr(Ws, mode="r")[0]
    dseq = np.abs(np.diag(R_seq))
    keep = np.flatnonzero(dseq > rtol * diag[0] * max(Ws.shape))
    if keep.size != rank:
        raise ModelError(
            f"base parameters: sequential QR kept {keep.size} columns but the rank is {rank}; "
            "the random samples are ill-conditioned (try another seed or more samples)"
        )
    s = W.shape[1]
    drop = np.setdiff1d(np.arange(s), keep)
    Hb = W[:, keep]
    Kd, *_ = np.linalg.lstsq(Hb, W[:, drop], rcond=None)
    K = np.zeros((rank, s))
    K[:, keep] = np.eye(rank)
    K[:, drop] = Kd
    K[np.abs(K) < COEFF_ZERO] = 0.0
    resid = np.linalg.norm(Hb @ K[:, drop] - W[:, drop]) / max(np.linalg.norm(W), 1.0)
    if resid > 1e-8:
        raise ModelError(f"base parameters: regrouping residual {resid:.2e} is too large")
    names_s = standard_names(
        joint_names,
        regressor.stribeck_velocity is not None,
        regressor.held_velocity is not None,
        regressor.quadratic,
    )
    return BaseParameters(keep, K, [names_s[i] for i in keep], names_s)
