"""Collision-threshold calibration from free-motion recordings (no contact anywhere).

For each joint j the threshold is linear in five features of the motion,
``thr = c0 + c1·|qd| + c2·|a| + c3·r + c4·s`` (see safety/collision.py), with c >= 0; the
standstill term c4·s is off unless asked for (``terms``). Calibration
finds the smallest such envelope over the free-motion residuals by a linear program,

    minimise  mean_k thr_k    subject to  thr_k >= |tau_ext_hat_k|  for every sample k,

then scales it by ``1 + margin``. Minimising the mean threshold keeps the resting threshold
c0 as low as the recordings allow (sensitivity to pushes on a still arm) while the other
terms absorb what motion adds: acceleration steps (inertia errors) and velocity reversals
(Coulomb friction switching).

``sustained=True`` fits the envelope to the residual *sustained over the debounce window*
(the running minimum of |tau_ext_hat| over the last ``debounce_time``) instead of single
samples: the monitor only trips on a residual that stays above the threshold that long, so
covering single-sample peaks adds margin no detection needs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linprog

from hofto_hw.config.collision import CollisionConfig
from hofto_hw.errors import UserError
from hofto_hw.identify.data import Recording
from hofto_hw.jit import compiled_or_python
from safety.collision import CollisionMonitor
from safety.collision.kernel import standstill_now

FloatArray = NDArray[np.float64]
TERMS = ("base", "velocity_gain", "acceleration_gain", "reversal_margin", "standstill_margin")
DEFAULT_TERMS = (True, True, True, True, False)


@dataclass
class Calibration:
    """A calibrated monitor config and what it was fitted on.

    ``peak`` (n,) largest |tau_ext_hat| [N·m] on the calibration data; ``envelope`` (n, 4)
    coefficients before the margin; ``samples`` count.
    """

    config: CollisionConfig
    envelope: FloatArray
    peak: FloatArray
    samples: int


def features(rec: Recording, template: CollisionConfig) -> FloatArray:
    """(N, n, 5) threshold features [1, |qd|, |a|, r, s] of ``rec`` under ``template``'s
    filter settings, computed by the monitor's own per-tick code (so they match replay)."""
    n = rec.n_joints
    unit = template.model_copy(
        update={
            "base": [1.0] * n,
            "velocity_gain": None,
            "acceleration_gain": None,
            "reversal_margin": None,
            "standstill_margin": None,
        }
    )
    mon = CollisionMonitor(unit)
    out = np.zeros((rec.n_samples, n, 5))
    out[:, :, 0] = 1.0
    out[:, :, 1] = np.abs(rec.qd)
    mon.reset(rec.qd[0])
    t, qd = rec.t, rec.qd
    for k in range(1, rec.n_samples):
        mon.features(qd[k], t[k] - t[k - 1])
        out[k, :, 2] = np.abs(mon.accel)
        out[k, :, 3] = mon.reversal
        out[k, :, 4] = mon.still
    out[0, :, 2:] = 0.0
    now = compiled_or_python(standstill_now, mon.backend)  # the monitor's own formula
    inv_v_still = 1.0 / template.standstill_velocity
    for j in range(n):
        out[0, j, 4] = now(rec.qd[0, j], inv_v_still)
    return out


def fit_envelope(
    feats: FloatArray,
    residual: FloatArray,
    use: tuple[bool, ...],
    min_base: float,
    rest_weight: float = 1.0,
) -> FloatArray:
    """Coefficients (5,) >= 0 of the smallest-mean envelope of |residual| for one joint.

    ``feats`` (N, 5), ``residual`` (N,) [N·m]; ``use`` (4 or 5 flags) switches terms on;
    c0 >= min_base. ``rest_weight`` W weighs each sample's threshold in the mean by
    1 + (W − 1)·s (s the standstill feature): W > 1 favours a low threshold at rest, where
    free-motion runs have few samples.
    """
    m = feats.shape[1]
    cols = [i for i in range(m) if i < len(use) and use[i]]
    F = feats[:, cols]
    r = np.abs(residual)
    # the objective is the mean threshold over *every* sample (taken before dropping rows:
    # over the kept rows alone a term that is small where the residual is large looks cheap)
    w = 1.0 + (rest_weight - 1.0) * feats[:, 4] if rest_weight != 1.0 else None
    cost = F.mean(axis=0) if w is None else (w[:, None] * F).sum(axis=0) / w.sum()
    # c0 >= min_base and features >= 0: rows with |r| <= min_base cannot bind.
    keep = r > min_base
    F, r = F[keep], r[keep]
    if r.size == 0:
        out = np.zeros(m)
        out[0] = min_base
        return out
    bounds = [(min_base, None)] + [(0.0, None)] * (len(cols) - 1)
    x = _solve_by_rows(cost, F, r, bounds)
    out = np.zeros(m)
    out[cols] = x
    return out


#: rows of the first subproblem of :func:`_solve_by_rows` (the largest residuals + a sample)
FIRST_ROWS = 2000


def _solve_by_rows(
    cost: FloatArray, F: FloatArray, r: FloatArray, bounds: list[tuple[float, float | None]]
) -> FloatArray:
    """argmin cost·c subject to F·c >= r and ``bounds``, by adding rows: solve on the largest
    residuals and a fixed sample, add the rows the solution violates, repeat. The answer meets
    every row, so it is the optimum of the whole program (only a sample of the tens of
    thousands of rows binds; measured 3x faster on the UR10e runs, same coefficients)."""

    def solve(rows: NDArray[np.intp] | slice) -> FloatArray:
        res = linprog(c=cost, A_ub=-F[rows], b_ub=-r[rows], bounds=bounds, method="highs")
        if res.status != 0:
            raise UserError(f"threshold calibration failed: {res.message}")
        return np.asarray(res.x)

    if r.size <= 2 * FIRST_ROWS:
        return solve(slice(None))
    rows = np.union1d(
        np.argsort(r)[-FIRST_ROWS // 4 :],
        np.random.default_rng(0).choice(r.size, FIRST_ROWS, replace=False),
    )
    while True:
        x = solve(rows)
        short = r - F @ x
        bad = np.setdiff1d(np.flatnonzero(short > 1e-9), rows)  # (the solver's tolerance)
        if bad.size == 0:
            return x
        rows = np.union1d(rows, bad[np.argsort(short[bad])[-FIRST_ROWS:]])


def sustained(rec: Recording, residual: FloatArray, window: float) -> FloatArray:
    """Running minimum of |residual| (N, n) over the last ``window`` seconds of ``rec.t``
    (the sample itself included): what stays above a level for the debounce time."""
    r = np.abs(residual)
    out = r.copy()
    if window <= 0.0:
        return out
    t = rec.t
    start = np.searchsorted(t, t - window + 1e-9, side="left")
    for k in range(r.shape[0]):
        if start[k] < k:
            out[k] = r[start[k] : k + 1].min(axis=0)
    return out


def fit_envelopes(
    feats: FloatArray,
    residual: FloatArray,
    terms: tuple[bool, ...] | list[tuple[bool, ...]],
    min_base: float,
) -> FloatArray:
    """Envelope coefficients (n, 5) for every joint: ``feats`` (N, n, 5) from
    :func:`features`, ``residual`` (N, n) [N·m] (already sustained if wanted); ``terms``
    one tuple of flags for all joints or one per joint."""
    n = residual.shape[1]
    per_joint = terms if isinstance(terms, list) else [terms] * n
    if len(per_joint) != n:
        raise UserError(f"threshold calibration: {len(per_joint)} term sets for {n} joints")
    flags = [tuple(t) + (False,) * (len(TERMS) - len(t)) for t in per_joint]
    return np.stack(
        [fit_envelope(feats[:, j], residual[:, j], flags[j], min_base) for j in range(n)]
    )


def config_from_envelope(
    template: CollisionConfig,
    env: FloatArray,
    margin: float | FloatArray,
    terms: tuple[bool, ...] | list[tuple[bool, ...]] = DEFAULT_TERMS,
) -> CollisionConfig:
    """``template`` with its per-joint terms set to ``env`` (n, 5) · (1 + margin); margin a
    number or one per joint. A term off for every joint is left out (None)."""
    n = env.shape[0]
    per_joint = terms if isinstance(terms, list) else [terms] * n
    flags = np.array([tuple(t) + (False,) * (len(TERMS) - len(t)) for t in per_joint])
    scale = 1.0 + np.broadcast_to(np.asarray(margin, dtype=float), (n,))
    scaled = env * scale[:, None]
    values: dict[str, list[float] | None] = {
        name: [float(v) for v in scaled[:, i]] for i, name in enumerate(TERMS)
    }
    for i, name in enumerate(TERMS[1:], start=1):
        if not flags[:, i].any():
            values[name] = None
    return template.model_copy(update=values)


def calibrate(
    recordings: list[Recording],
    residuals: list[FloatArray],
    template: CollisionConfig,
    *,
    margin: float | list[float] = 0.5,
    min_base: float = 1.0,
    terms: tuple[bool, ...] | list[tuple[bool, ...]] = DEFAULT_TERMS,
    sustain: bool = False,
) -> Calibration:
    """Thresholds covering every sample of ``residuals`` (each (N_i, n) [N·m]) with a margin.

    ``template`` gives the filter, debounce, hysteresis, reversal and standstill timing; its
    per-joint values are replaced. ``margin`` 0.5 puts the thresholds 50 % above the envelope
    (a number, or one per joint). ``terms``: which of base, velocity, acceleration, reversal,
    standstill to fit (one tuple, or one per joint); ``sustain``: fit the residuals sustained
    over ``template.debounce_time`` (see :func:`sustained`).
    """
    if not recordings:
        raise UserError("thresholds calibrate: no recordings given")
    feats = np.concatenate([features(rec, template) for rec in recordings])
    if sustain:
        residuals = [
            sustained(rec, r, template.debounce_time)
            for rec, r in zip(recordings, residuals, strict=True)
        ]
    resid = np.concatenate(residuals)
    env = fit_envelopes(feats, resid, terms, min_base)
    cfg = config_from_envelope(template, env, np.asarray(margin, dtype=float), terms)
    return Calibration(cfg, env, np.max(np.abs(resid), axis=0), int(resid.shape[0]))
