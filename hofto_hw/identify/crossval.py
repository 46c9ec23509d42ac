"""Leave-runs-out cross-validation of an identification setting.

Every run is folded once into its own per-joint QR factor (``estimate.Accumulator``); a fold's
training system is the QR of the stacked factors of its training runs, so k folds cost k small
solves, not k passes over the data. The held-out error of a run is exact
(``Accumulator.joint_residuals``). The figure of merit is the per-joint RMSE [N·m] over all
held-out samples: sqrt(Σ_runs ||e_j||² / Σ_runs N).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from hofto_hw.identify.base_params import find_base_parameters
from hofto_hw.identify.consistent import consistent_fit
from hofto_hw.identify.estimate import Accumulator, least_squares
from hofto_hw.identify.pipeline import Samples, nominal_theta
from hofto_hw.identify.regressor import Regressor
from hofto_hw.model.robot import RobotModel


def merge(accs: Sequence[Accumulator]) -> Accumulator:
    """One accumulator holding the stacked systems of ``accs`` (same regressor and base)."""
    first = accs[0]
    out = Accumulator(first.regressor, first.base, chunk=1)
    for j in range(first.n):
        A = np.vstack([a.R[j] for a in accs])
        r = scipy.linalg.qr(A, mode="r", check_finite=False)[0]
        k = min(r.shape[0], first.p + 1)
        out.R[j, :k] = r[:k]
    out.samples = sum(a.samples for a in accs)
    out.tau_sq = np.sum([a.tau_sq for a in accs], axis=0)
    return out


@dataclass
class CrossValidation:
    """Held-out RMSE [N·m] per joint over all folds (n,), and per run (runs, n)."""

    rmse: np.ndarray
    run_rmse: np.ndarray
    sources: list[str]


def leave_runs_out(
    model: RobotModel,
    runs: Sequence[Samples],
    folds: Sequence[Sequence[int]],
    *,
    method: str = "wls",
    smooth_velocity: float = 0.02,
    held_velocity: float | None = None,
    quadratic: bool = False,
    held_passive: bool = False,
) -> CrossValidation:
    """Fit on all runs but each fold's, test on the fold's runs (indices into ``runs``).

    ``method``: ``ols``, ``wls`` or ``consistent`` (the physically consistent SDP through the
    WLS factor, as :func:`~hofto_hw.identify.pipeline.identify` does).
    """
    reg = Regressor(model.pin_model, smooth_velocity, None, held_velocity, quadratic, held_passive)
    base = find_base_parameters(reg, model.joint_names)
    accs = []
    for run in runs:
        acc = Accumulator(reg, base)
        acc.add(run.q, run.qd, run.qdd, run.tau)
        accs.append(acc)
    n = model.n
    sq = np.zeros((len(runs), n))
    prior = nominal_theta(model, False, held_velocity is not None, quadratic)
    for fold in folds:
        train = merge([a for i, a in enumerate(accs) if i not in set(fold)])
        ols = least_squares(train)
        if method == "consistent":
            w = 1.0 / np.maximum(ols.residual_std, 1e-9)
            mu = base.from_standard(consistent_fit(train.combined(w), base, prior, n))
        elif method == "wls":
            mu = least_squares(train, weighted=True).mu
        else:
            mu = ols.mu
        for i in fold:
            sq[i] = accs[i].joint_residuals(mu) ** 2
    counts = np.array([a.samples for a in accs], dtype=float)
    tested = sorted({i for f in folds for i in f})
    rmse = np.sqrt(sq[tested].sum(axis=0) / counts[tested].sum())
    return CrossValidation(rmse, np.sqrt(sq / counts[:, None]), [r.source for r in runs])
