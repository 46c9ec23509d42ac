"""The collision monitor's one tick in one call (numba), and the formulas it is made of.

The ONE implementation of the monitor's arithmetic: :func:`threshold` (the threshold formula
of safety/collision/__init__.py, which the loop, flight-log replay, calibration and tuning all
call), :func:`features_step` (the threshold features a, moving, r, s), :func:`monitor_step`
(a whole tick) and :func:`monitor_tick` (the same on the packed state). Backend ``numba``
runs them compiled; backend ``python`` runs the top-level function's own Python source
(``py_func``; :func:`hofto_hw.jit.compiled_or_python`), and with numba's
``NUMBA_DISABLE_JIT=1`` every line runs as Python. The numpy implementation this replaced is
the reference in tests/safety/collision/reference.py (tests/safety/collision/test_kernel.py:
agreement to 1e-12 over thousands of random steps, NaN/inf included).

Joint by joint, no fastmath (so no fused multiply-add). Writes only into the arrays passed
in; allocates nothing. The compilation conventions (``cache=True``, warmed when the monitor
is built) are every kernel's (:mod:`hofto_hw.jit`).
"""

from __future__ import annotations

import math

import numpy as np

from hofto_hw.jit import jit, jit_inline
from safety.collision.state import flags_of

_flags_of = jit(flags_of)  # the Python side's own function, compiled: one definition

# indices repeated from params.py / state.py as plain ints (numba reads module globals as
# compile-time constants); tests/safety/collision/test_kernel.py checks they agree
S_V_REV, S_TAU_A, S_MOVING_TIME, S_REVERSAL_TIME, S_V_STILL, S_STILL_TIME = 0, 1, 2, 3, 4, 5
S_ACCEL_LEVEL, S_PHASE_HOLD, S_TRIP_AFTER, S_RELEASE_AFTER, S_RELEASE_RATIO = 6, 7, 8, 9, 10
S_LOGIC = 11
N_SCAL = 12
F_QD_PREV, F_ACCEL, F_MOVING, F_REVERSAL, F_STILL, F_QD_OK = 0, 1, 2, 3, 4, 5
ST_STARTED, ST_PHASE_LEFT, ST_ACCEL_PHASE = 0, 1, 2
L_THR, L_RATIO, L_ABOVE, L_BELOW = 0, 1, 2, 3
LOGIC_ANY, LOGIC_ALL, LOGIC_MEAN = 0, 1, 2
COLLIDED, CONTACT, NONFINITE = 1, 2, 4


@jit_inline
def threshold(base, kv, ka, kr, ks, aq, aa, rev, still):  # type: ignore[no-untyped-def]
    """The collision threshold [N·m]: thr = kv·|qd| + base + ka·|a| + kr·r + ks·s, summed in
    this order (the sums are rounded), from the gains of one level/row/joint (base of the
    phase) and the features |qd| ``aq`` [rad/s], |a| ``aa`` [rad/s²], reversal ``rev`` and
    standstill ``still`` (safety/collision/__init__.py). Floats in the kernels; as Python
    (``threshold.py_func``) numpy arrays broadcast, which is how tuning evaluates it over a
    whole recording (hofto_hw.replay.tuning.thresholds_of)."""
    t = aq * kv
    t = t + base
    t = t + aa * ka
    t = t + rev * kr
    t = t + still * ks
    return t


@jit_inline
def standstill_now(v: float, inv_v_still: float) -> float:
    """The standstill indicator of one velocity sample, exp(-(v/v_s)²) in [0, 1] (v [rad/s],
    ``inv_v_still`` = 1/v_s [s/rad]); :func:`features_step` low-passes it, calibration's
    first sample (hofto_hw/replay/calibrate.py) takes it as is."""
    z = v * inv_v_still
    return math.exp(-(z * z))


@jit_inline
def features_step(feat: np.ndarray, sst: np.ndarray, bad_qd: np.ndarray, scal: np.ndarray,
                  qd: np.ndarray, dt: float) -> None:  # fmt: skip
    """Advance the threshold features ``feat`` (6, n) (state.py's rows) by dt [s] on qd (n,)
    [rad/s]: the low-passed acceleration, the moving, reversal and standstill indicators;
    ``bad_qd`` (n,) bool := qd not finite. A joint with a non-finite qd keeps its accel,
    moving and reversal and uses its last finite velocity. ``sst`` (3,) marks the start (the
    first call seeds qd_prev)."""
    n = qd.shape[0]
    if sst[ST_STARTED] == 0.0:
        for j in range(n):
            feat[F_QD_PREV, j] = qd[j] if math.isfinite(qd[j]) else 0.0
        sst[ST_STARTED] = 1.0
    v_rev = scal[S_V_REV]
    alpha = dt / (scal[S_TAU_A] + dt)
    inv_dt = 1.0 / dt
    inv_v_rev = 1.0 / v_rev
    inv_v_still = 1.0 / scal[S_V_STILL]
    decay_moving = math.exp(-dt / scal[S_MOVING_TIME])
    decay_rev = math.exp(-dt / scal[S_REVERSAL_TIME])
    T = scal[S_STILL_TIME]
    rise = 1.0 - math.exp(-dt / T) if T > 0.0 else 1.0
    for j in range(n):
        bq = not math.isfinite(qd[j])
        bad_qd[j] = bq
        v = feat[F_QD_PREV, j] if bq else qd[j]
        feat[F_QD_OK, j] = v
        x = (v - feat[F_QD_PREV, j]) * inv_dt
        x = x - feat[F_ACCEL, j]
        x = x * alpha
        accel = feat[F_ACCEL, j] + x
        feat[F_QD_PREV, j] = v
        moving = feat[F_MOVING, j] * decay_moving
        if abs(v) > v_rev:
            moving = max(moving, 1.0)
        y = v * inv_v_rev
        rev_now = math.exp(-(y * y)) * moving
        rev = max(feat[F_REVERSAL, j] * decay_rev, rev_now)
        if not bq:
            feat[F_ACCEL, j] = accel
            feat[F_MOVING, j] = moving
            feat[F_REVERSAL, j] = rev
        now = standstill_now(v, inv_v_still)
        if T <= 0.0:
            feat[F_STILL, j] = now
        else:
            s = feat[F_STILL, j]
            feat[F_STILL, j] = min(now, (now - s) * rise + s)


@jit
def monitor_tick(
    fbuf: np.ndarray,
    bbuf: np.ndarray,
    first_tick: np.ndarray,
    tau: np.ndarray,
    qd: np.ndarray,
    qdd: np.ndarray,
    dt: float,
    tick: int,
) -> int:
    """One tick on the packed state (safety/collision/state.py MonitorState.fbuf/bbuf):
    tau (k, n) [N·m], qd (n,) [rad/s], qdd (n,) [rad/s²], dt [s], tick (first crossings).
    Returns the tick's flags (state.py ``flags_of``): COLLIDED | CONTACT | NONFINITE."""
    k = tau.shape[0]
    n = qd.shape[0]
    per_level = 6 * k * n + 4 * (k + 1) * n
    L = (fbuf.shape[0] - N_SCAL - 6 * n - 3) // per_level
    a = 0
    par = fbuf[a : a + L * 6 * k * n].reshape((L, 6, k, n))
    a += L * 6 * k * n
    scal = fbuf[a : a + N_SCAL]
    a += N_SCAL
    feat = fbuf[a : a + 6 * n].reshape((6, n))
    a += 6 * n
    sst = fbuf[a : a + 3]
    a += 3
    lev = fbuf[a : a + L * 4 * (k + 1) * n].reshape((L, 4, k + 1, n))
    b = 0
    deciding = bbuf[b : b + k]
    b += k
    joints = bbuf[b : b + L * (k + 1) * n].reshape((L, k + 1, n))
    b += L * (k + 1) * n
    bad = bbuf[b : b + (k + 3) * n].reshape((k + 3, n))
    b += (k + 3) * n
    row_hit = bbuf[b : b + L * (k + 1)].reshape((L, k + 1))
    b += L * (k + 1)
    level_joints = bbuf[b : b + L * n].reshape((L, n))
    b += L * n
    hits = bbuf[b : b + L + 1]
    monitor_step(
        par, scal, deciding, feat, sst, lev, joints, bad, row_hit, level_joints, hits,
        first_tick, tau, qd, qdd, dt, tick,
    )  # fmt: skip
    return _flags_of(hits)


@jit
def monitor_step(
    par: np.ndarray,
    scal: np.ndarray,
    deciding: np.ndarray,
    feat: np.ndarray,
    sst: np.ndarray,
    lev: np.ndarray,
    joints: np.ndarray,
    bad: np.ndarray,
    row_hit: np.ndarray,
    level_joints: np.ndarray,
    hits: np.ndarray,
    first_tick: np.ndarray,
    tau: np.ndarray,
    qd: np.ndarray,
    qdd: np.ndarray,
    dt: float,
    tick: int,
) -> None:
    """One tick; arrays as in safety/collision/state.py and params.py."""
    L = par.shape[0]
    k = par.shape[2]
    n = par.shape[3]
    # ---- features (joints with a non-finite qd keep accel/moving/reversal)
    features_step(feat, sst, bad[k + 1], scal, qd, dt)
    # ---- non-finite estimates (the fused row's only for the mean fusion)
    logic = int(scal[S_LOGIC])
    any_bad = False
    for j in range(n):
        nf = bad[k + 1, j]
        bf = False
        for r in range(k):
            b = not math.isfinite(tau[r, j])
            bad[r, j] = b
            nf = nf or b
            if deciding[r]:
                bf = bf or b
        bad[k, j] = bf and logic == LOGIC_MEAN
        bad[k + 2, j] = nf
        any_bad = any_bad or nf
    hits[L] = any_bad
    # ---- phase
    fast = False
    for j in range(n):
        if abs(qdd[j]) > scal[S_ACCEL_LEVEL]:
            fast = True
    if fast:
        sst[ST_PHASE_LEFT] = scal[S_PHASE_HOLD]
    else:
        sst[ST_PHASE_LEFT] -= dt
    phase = 1 if sst[ST_PHASE_LEFT] > 0.0 else 0
    sst[ST_ACCEL_PHASE] = phase
    # ---- thresholds, ratios, fused row, debounce and hysteresis
    trip_after = scal[S_TRIP_AFTER]
    release_after = scal[S_RELEASE_AFTER]
    release_ratio = scal[S_RELEASE_RATIO]
    n_dec = 0
    for r in range(k):
        if deciding[r]:
            n_dec += 1
    for lv in range(L):
        for j in range(n):
            aq = abs(feat[F_QD_OK, j])
            aa = abs(feat[F_ACCEL, j])
            fused = 0.0
            for r in range(k):
                t = threshold(
                    par[lv, phase, r, j], par[lv, 2, r, j], par[lv, 3, r, j], par[lv, 4, r, j],
                    par[lv, 5, r, j], aq, aa, feat[F_REVERSAL, j], feat[F_STILL, j],
                )  # fmt: skip
                lev[lv, L_THR, r, j] = t
                a = 0.0 if bad[r, j] else abs(tau[r, j])
                ratio = a / t
                lev[lv, L_RATIO, r, j] = ratio
                if deciding[r]:
                    fused += ratio
            if logic == LOGIC_MEAN:
                fused = fused / n_dec
                lev[lv, L_RATIO, k, j] = 0.0 if bad[k, j] else fused
            for r in range(k + 1):
                if not bad[r, j]:
                    ratio = lev[lv, L_RATIO, r, j]
                    above = lev[lv, L_ABOVE, r, j] + dt
                    lev[lv, L_ABOVE, r, j] = above if ratio > 1.0 else 0.0
                    below = lev[lv, L_BELOW, r, j] + dt
                    lev[lv, L_BELOW, r, j] = below if ratio < release_ratio else 0.0
                on = joints[lv, r, j] or lev[lv, L_ABOVE, r, j] >= trip_after
                joints[lv, r, j] = on and not lev[lv, L_BELOW, r, j] >= release_after
    # ---- decisions and first crossings
    for lv in range(L):
        for r in range(k + 1):
            h = False
            for j in range(n):
                h = h or joints[lv, r, j]
            row_hit[lv, r] = h
        if logic == LOGIC_MEAN:
            hits[lv] = row_hit[lv, k]
            for j in range(n):
                level_joints[lv, j] = joints[lv, k, j]
        else:
            hit = False
            every = True
            for j in range(n):
                level_joints[lv, j] = False
            for r in range(k):
                if not deciding[r]:
                    continue
                for j in range(n):
                    level_joints[lv, j] = level_joints[lv, j] or joints[lv, r, j]
                if row_hit[lv, r]:
                    hit = True
                else:
                    every = False
            hits[lv] = hit and (every or logic == LOGIC_ANY)
    for r in range(k):
        if row_hit[L - 1, r] and first_tick[r] < 0:
            first_tick[r] = tick
