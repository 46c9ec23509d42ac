"""Physically consistent identification: a standard parameter set whose every link has a
positive semidefinite pseudo-inertia (Wensing et al., 2017), fitted to the data as an SDP.

For link j with pinocchio parameters (m, h = m·c, I about the frame origin) the pseudo-inertia

    J = [[Σ, h], [hᵀ, m]],   Σ = ½·tr(I)·1₃ − I   (so I = tr(Σ)·1₃ − Σ)

is PSD exactly when a real mass distribution with those moments exists (mass >= 0, inertia
PSD, triangle inequalities). The SDP works on J_j directly, plus rotor inertia >= 0 and
Coulomb, viscous friction and the Stribeck gap >= 0:

    minimize  ||R11·K·theta − r||² / ||r||²  +  lam·||theta_rigid − theta_prior||² / ||prior||²

with (R11, r) the triangular factor of the (weighted) stacked base regressor (estimate.py);
the small prior term fixes the directions the data cannot see (the regrouped parameters).
"""

from __future__ import annotations

import warnings

import cvxpy as cp
import numpy as np

from hofto_hw.errors import UserError
from hofto_hw.identify.base_params import BaseParameters
from hofto_hw.identify.regressor import N_RIGID
from hofto_hw.identify.threads import one_blas_thread

# Σ entries (row, col) feeding I's pinocchio components: Ixx, Ixy, Iyy, Ixz, Iyz, Izz.


def _link_params(J: cp.Variable) -> list[cp.Expression]:
    """Pinocchio order m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz from a 4x4 pseudo-inertia."""
    tr = J[0, 0] + J[1, 1] + J[2, 2]
    return [
        J[3, 3],
        J[0, 3],
        J[1, 3],
        J[2, 3],
        tr - J[0, 0],
        -J[0, 1],
        tr - J[1, 1],
        -J[0, 2],
        -J[1, 2],
        tr - J[2, 2],
    ]


def pseudo_inertia(pi: np.ndarray) -> np.ndarray:
    """The 4x4 pseudo-inertia of one link's 10 pinocchio parameters."""
    m, mx, my, mz, ixx, ixy, iyy, ixz, iyz, izz = pi
    I = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    S = 0.5 * np.trace(I) * np.eye(3) - I
    J = np.zeros((4, 4))
    J[:3, :3] = S
    J[:3, 3] = J[3, :3] = (mx, my, mz)
    J[3, 3] = m
    return J


def is_consistent(inertial: np.ndarray, tol: float = 1e-9) -> bool:
    """True when every link's pseudo-inertia is PSD (inertial shape (10·n,))."""
    links = np.asarray(inertial).reshape(-1, N_RIGID)
    return all(np.linalg.eigvalsh(pseudo_inertia(p))[0] >= -tol for p in links)


@one_blas_thread
def consistent_fit(
    R: np.ndarray,
    base: BaseParameters,
    prior: np.ndarray,
    n: int,
    lam: float = 1e-5,
    margin: float = 1e-6,
) -> np.ndarray:
    """Physically consistent standard parameters theta (14·n,) fitted through R (p+1, p+1).

    ``prior`` (14·n,) or (15·n,): nominal standard parameters (e.g. URDF values) for the unseen
    directions; ``margin`` keeps each J_j >= margin·1 [kg·m²] (strictly physical).
    """
    p = base.p
    R11, r = R[:p, :p], R[:p, p]
    Js = [cp.Variable((4, 4), PSD=True) for _ in range(n)]
    n_extra = prior.size - N_RIGID * n  # rotor inertia, Fc, Fv, B (, Stribeck gap)
    extra = cp.Variable(n_extra)
    rigid = [e for J in Js for e in _link_params(J + margin * np.eye(4))]
    theta = cp.hstack([*rigid, extra])
    mu = base.K @ theta
    r_norm = max(float(np.linalg.norm(r)), 1e-12)
    prior_rigid = prior[: N_RIGID * n]
    p_norm = max(float(np.linalg.norm(prior_rigid)), 1e-12)
    # Norms rather than squares: the solver's tolerance then bounds the residual itself, not
    # its square, which keeps poorly excited parameters accurate.
    objective = (
        cp.norm(R11 @ mu - r) / r_norm + lam * cp.norm(cp.hstack(rigid) - prior_rigid) / p_norm
    )
    # Ia, Fc, Fv, the Stribeck gap (Fs >= Fc) and held friction are >= 0; B and Q are free.
    kinds = [nm.rsplit(".", 1)[1] for nm in base.standard_names[N_RIGID * n :]]
    nonneg = [i for i, k in enumerate(kinds) if k in ("Ia", "Fc", "Fv", "S", "H")]
    constraints = [extra[nonneg] >= 0.0]
    problem = cp.Problem(cp.Minimize(objective), constraints)
    try:
        with warnings.catch_warnings():
            # "optimal_inaccurate" is checked below; cvxpy's warning would only repeat it.
            warnings.simplefilter("ignore", UserWarning)
            problem.solve(solver=cp.CLARABEL, tol_gap_abs=1e-11, tol_gap_rel=1e-11, tol_feas=1e-11)
    except cp.error.SolverError:
        problem.solve(solver=cp.SCS, eps=1e-9, max_iters=200000)
    if problem.status not in ("optimal", "optimal_inaccurate") or theta.value is None:
        raise UserError(f"identify: the physically consistent fit failed ({problem.status})")
    return np.asarray(theta.value, dtype=float)
