"""The observers' arithmetic: one per-joint kernel per observer, compiled by numba.

On six joints an observer update is a few hundred floating-point operations; done as numpy
calls on six-element arrays, the time goes to the ~0.5 µs each call costs, not to arithmetic.
Each kernel does one observer update (every stage, every joint, substeps, M·z3) in one call,
and these kernels are the only implementation of the observers' formulas in the package: an
observer calls its kernel compiled (backend ``numba``) or the same source run by the
interpreter (backend ``python``); compilation, the backends and the switch that turns compiled
code off are :mod:`hofto_hw.jit`'s. The numpy formulation of the paper's equations is kept in
tests/hofto_hw/observers/reference.py, where tests/hofto_hw/observers/test_kernels.py checks
both backends against it to 1e-12 over thousands of random steps, Remark 7's equivalences and
non-finite samples included. Kernels write only into the arrays passed in; none allocates.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import literal_unroll

from hofto_hw.jit import jit, jit_inline

# ----------------------------------------------------------------- scalar helpers


@jit
def _sign(x: float) -> float:
    """np.sign for one float: -1, 0, 1 (NaN stays NaN)."""
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return x * 0.0  # 0 -> 0, NaN -> NaN


@jit
def _sig_log(x: float, a: float, p: float, log2a: float) -> float:
    """sig^p(x) = |x|^p·sign(x) for a = |x| and log2a = log2(a): sign for p = 0, x for
    p = 1, roots for p = 1/2, 1/4, 3/4, else 2^(p·log2 a).

    libm's pow costs ~14 ns; sqrt ~1, log2 ~4, exp2 ~3, and the stages of eq. (17) raise the
    same |e| to several powers, so one log2 serves them all. Rounding only: 2^(p·log2 a)
    is |x|^p to ~|p·log2 a|·2^-53 relative (1e-15 at |x| = 1e-6), the roots to ~2 ulp.
    Non-finite and zero arguments give pow's results: a = 0 → log2 = -inf → 0, a = inf →
    inf, NaN → NaN (the copysign keeps the sign of x as before)."""
    if p == 0.0:
        return _sign(x)
    if p == 1.0:
        return x
    if p == 0.5:
        return math.copysign(math.sqrt(a), x)
    if p == 0.25:
        return math.copysign(math.sqrt(math.sqrt(a)), x)
    if p == 0.75:
        r = math.sqrt(a)
        return math.copysign(r * math.sqrt(r), x)
    return math.copysign(math.exp2(p * log2a), x)


@jit
def _log2(a: float) -> float:
    """math.log2 of a = |x|, -inf at zero as compiled (C's log2); Python's math.log2(0) raises,
    and NUMBA_DISABLE_JIT runs these kernels as Python."""
    return math.log2(a) if a != 0.0 else -math.inf


@jit
def _needs_log(p: float) -> bool:
    """True when :func:`_sig_log` reads log2a for power p."""
    return p != 0.0 and p != 1.0 and p != 0.5 and p != 0.25 and p != 0.75


@jit
def _mat_vec(M: np.ndarray, x: np.ndarray, out: np.ndarray) -> None:
    n = M.shape[0]
    for i in range(n):
        acc = 0.0
        for k in range(n):
            acc += M[i, k] * x[k]
        out[i] = acc


# ----------------------------------------------------------------- HOFTO (any order)


@jit
def hofto_step(
    z: np.ndarray,
    neg_gains: np.ndarray,
    powers: np.ndarray,
    T: np.ndarray,
    y: np.ndarray,
    y_prev: np.ndarray,
    a: np.ndarray,
    h: float,
    a_h2: float,
    recursive: bool,
    taylor: bool,
    substeps: int,
    col: np.ndarray,
) -> None:
    """One HOFTO sample period for every joint (see :class:`~hofto_hw.observers.hofto.HoftoCore`).

    z (s, j) states, updated in place; neg_gains (s, j) = -L; powers (s,); T (s, s) the
    chain's transition matrix for step h; y, y_prev, a (j,); col (2, s) scratch.
    """
    s, joints = z.shape
    inj = col[0]
    if taylor:
        # substeps outside, joints inside: the prediction runs along rows of z (contiguous,
        # all joints at once) and consecutive joints' injections do not depend on each other;
        # each joint's arithmetic is the one joint-by-joint order does, in the same order
        for k in range(substeps):
            _predict(z, T, a, h, a_h2)
            for jj in range(joints):
                yk = _held(y, y_prev, jj, k, substeps)
                _injection(z, jj, yk, neg_gains, powers, recursive, inj, h, True)
        return
    zz = col[1]
    for jj in range(joints):  # euler: inject with the state before the prediction
        step = (y[jj] - y_prev[jj]) / substeps
        yk = y_prev[jj]
        for _ in range(substeps):
            if substeps == 1:
                yk = y[jj]
            else:
                yk = yk + step
            _injection(z, jj, yk, neg_gains, powers, recursive, inj, h, False)
            # prediction along the chain: zz = T·z (upper triangular)
            for i in range(s):
                acc = 0.0
                for m in range(i, s):
                    acc += T[i, m] * z[m, jj]
                zz[i] = acc
            for i in range(s):
                z[i, jj] = zz[i] + inj[i] * h
            z[1, jj] = z[1, jj] + a[jj] * h


@jit_inline
def _injection(
    z: np.ndarray,
    jj: int,
    y: float,
    neg_gains: np.ndarray,
    powers: np.ndarray,
    recursive: bool,
    inj: np.ndarray,
    h: float,
    apply: bool,
) -> None:
    """Output-injection terms of joint jj: into inj (s,), or with ``apply`` added to z at
    once as z_i += inj_i·h (inj untouched; each stage reads only z_i, z_{i+1} of before)."""
    s = z.shape[0]
    if recursive:
        prev = y
        for i in range(s):
            d = z[i, jj] - prev
            p = powers[i]
            a = abs(d)
            v = _sig_log(d, a, p, _log2(a) if _needs_log(p) else 0.0) * neg_gains[i, jj]
            if i < s - 1:
                prev = z[i + 1, jj] + v
            if apply:
                z[i, jj] = z[i, jj] + v * h
            else:
                inj[i] = v
    else:
        # every stage raises the same |e1|: one log2 for all of them
        e = y - z[0, jj]
        a = abs(e)
        log2a = 0.0
        have = False
        for i in range(s):
            p = powers[i]
            if not have and _needs_log(p):
                log2a = _log2(a)
                have = True
            v = -(_sig_log(e, a, p, log2a) * neg_gains[i, jj])
            if apply:
                z[i, jj] = z[i, jj] + v * h
            else:
                inj[i] = v


@jit_inline
def _predict(z: np.ndarray, T: np.ndarray, a: np.ndarray, h: float, a_h2: float) -> None:
    """z = T·z (the chain's prediction, upper triangular) for every joint, in place: row i
    reads rows >= i, not yet predicted; summed from T[i, i]·z_i up, as a dot product; then
    the model acceleration's terms z2 += a·h, z1 += a·a_h2."""
    s, joints = z.shape
    for i in range(s):
        t = T[i, i]
        for jj in range(joints):
            z[i, jj] = 0.0 + t * z[i, jj]
        for m in range(i + 1, s):
            t = T[i, m]
            for jj in range(joints):
                z[i, jj] = z[i, jj] + t * z[m, jj]
    for jj in range(joints):
        z[1, jj] = z[1, jj] + a[jj] * h
        z[0, jj] = z[0, jj] + a[jj] * a_h2


@jit_inline
def _held(y: np.ndarray, y_prev: np.ndarray, jj: int, k: int, substeps: int) -> float:
    """Joint jj's measured position at substep k (first-order hold): y at one substep, else
    y_prev + step + ... + step (k + 1 times, as summed substep by substep)."""
    if substeps == 1:
        return y[jj]
    step = (y[jj] - y_prev[jj]) / substeps
    yk = y_prev[jj]
    for _ in range(k + 1):
        yk = yk + step
    return yk


@jit_inline
def hofto_advance(
    z: np.ndarray,
    neg_gains: np.ndarray,
    powers: np.ndarray,
    prev: np.ndarray,
    work: np.ndarray,
    substeps: int,
    flags: int,
    y: np.ndarray,
    a: np.ndarray,
    dt: float,
) -> None:
    """One sample period dt [s] of a HOFTO (the fields of ``HoftoCore.record``): the step
    terms of h = dt/substeps (T, [h, a_h2] in ``work``) when h changed, :func:`hofto_step`
    with the sample y and the model acceleration a (joints,), then prev = y.

    Arrays, not the record, so that one compilation serves every order and joint count."""
    s = z.shape[0]
    T, hs = work[:s], work[s]
    taylor = (flags & BANK_TAYLOR) != 0
    h = dt / substeps
    if h != hs[0]:
        _hofto_transition(T, hs, h, taylor)
    recursive = (flags & BANK_RECURSIVE) != 0
    hofto_step(
        z, neg_gains, powers, T, y, prev, a, h, hs[1], recursive, taylor, substeps, work[s + 1 :]
    )
    for jj in range(y.shape[0]):
        prev[jj] = y[jj]


@jit
def hofto_update(
    record: np.ndarray, y: np.ndarray, a: np.ndarray, dt: float, M: np.ndarray, out: np.ndarray
) -> None:
    """:func:`hofto_advance` of a ``HoftoCore.record`` (shape (1,)), then out = M·z3 [N·m]:
    the HOFTO observer's update."""
    c = record[0]
    z = c["z"]
    hofto_advance(
        z, c["neg_gains"], c["powers"], c["prev"], c["work"], c["substeps"], c["flags"], y, a, dt
    )
    _mat_vec(M, z[2], out)


# ----------------------------------------------------------------- ESO and STA (Euler)


@jit_inline
def euler_step(
    z: np.ndarray,
    gains: np.ndarray,
    y: np.ndarray,
    y_prev: np.ndarray,
    a: np.ndarray,
    h: float,
    substeps: int,
    sta: bool,
) -> None:
    """ESO eq. (5) or, with ``sta``, the super-twisting observer (Remark 7): explicit Euler
    with substeps of h [s] (q held first-order, a held); z (3, j) states, gains (3, j) k1..k3
    (ESO) or l1..l3 (STA); y_prev = y after. The STA injects sig^(1/2)(e) and sign(e) where
    the ESO injects e."""
    for jj in range(y.shape[0]):
        step = (y[jj] - y_prev[jj]) / substeps
        yk = y_prev[jj]
        z1, z2, z3 = z[0, jj], z[1, jj], z[2, jj]
        for _ in range(substeps):
            yk = yk + step
            e = yk - z1
            u = u3 = e
            if sta:
                u, u3 = _sig_log(e, abs(e), 0.5, 0.0), _sign(e)
            z1, z2, z3 = (
                z1 + (gains[0, jj] * u + z2) * h,
                z2 + (gains[1, jj] * u + z3 + a[jj]) * h,
                z3 + (gains[2, jj] * u3) * h,
            )
        z[0, jj], z[1, jj], z[2, jj] = z1, z2, z3
        y_prev[jj] = y[jj]


@jit
def euler_update(
    z: np.ndarray,
    gains: np.ndarray,
    y: np.ndarray,
    y_prev: np.ndarray,
    a: np.ndarray,
    h: float,
    substeps: int,
    sta: bool,
    M: np.ndarray,
    out: np.ndarray,
) -> None:
    """:func:`euler_step`, then out = M·z3 [N·m]: the ESO's or the STA's update."""
    euler_step(z, gains, y, y_prev, a, h, substeps, sta)
    _mat_vec(M, z[2], out)


# ----------------------------------------------------------------- momentum, DOB


@jit_inline
def momentum_update(
    M: np.ndarray,
    qd: np.ndarray,
    tau: np.ndarray,
    f: np.ndarray,
    g: np.ndarray,
    ct_qd: np.ndarray,
    gain: np.ndarray,
    p0: np.ndarray,
    integral: np.ndarray,
    r: np.ndarray,
    dt: float,
) -> None:
    """Generalized-momentum residual: integral += (tau - f - g + Cᵀ·qd + r)·dt;
    r = K_O·(M·qd - p0 - integral)."""
    n = qd.shape[0]
    for i in range(n):
        integral[i] = integral[i] + (tau[i] - f[i] - g[i] + ct_qd[i] + r[i]) * dt
    for i in range(n):
        p = 0.0
        for k in range(n):
            p += M[i, k] * qd[k]
        r[i] = gain[i] * (p - p0[i] - integral[i])


@jit
def dob_update(
    gj: np.ndarray,
    cutoff: np.ndarray,
    w: np.ndarray,
    work: np.ndarray,
    qd: np.ndarray,
    tau: np.ndarray,
    nle: np.ndarray,
    f: np.ndarray,
    dt: float,
    out: np.ndarray,
) -> None:
    """DOB over dt [s]: the discrete pole alpha = 1 - exp(-g·dt) (work (2, n): [dt it was
    computed for (< 0: none yet)], alpha; recomputed only when dt changes), then
    u = g·Jn·qd + tau - nle - f; w += alpha·(u - w); out = g·Jn·qd - w."""
    alpha = work[1]
    if dt != work[0, 0]:
        for i in range(alpha.shape[0]):
            alpha[i] = -math.expm1(cutoff[i] * -dt)
        work[0, 0] = dt
    for i in range(qd.shape[0]):
        gq = gj[i] * qd[i]
        u = gq + tau[i] - nle[i] - f[i]
        w[i] = w[i] + (u - w[i]) * alpha[i]
        out[i] = gq - w[i]


# ----------------------------------------------------------------- the observer bank
#
# One call updates every observer of a tick (hofto_hw.observers.bank) on the observers' own
# arrays: ``obs`` holds one tuple per kind (None when the bank has none of that kind), each a
# tuple per observer of its output row, its arrays and its integers (the BANK_* layouts
# below); ``terms`` the snapshot's M (n, n), model acceleration, friction, gravity, Cᵀ·qd and
# C·qd + g (n,). Numba types every array by its own dtype, shape and layout and keeps it
# alive while it runs: nothing is addressed by hand.

#: per-observer tuples: (row, HoftoCore.record: z (s, n), neg_gains (s, n), powers (s,), prev
#: (n,), work (s + 3, s): T, [h, a_h2], col (2, s), substeps, flags); (row,
#: MomentumObserver.record: gain, p0, integral, r (n,));
#: (row, z (3, n), gains (3, n), y_prev (n,), substeps) for ESO and STA;
#: (row, g·Jn, cutoff, w (n,), work (2, n): [dt of alpha], alpha)
BANK_HOFTO, BANK_MOMENTUM, BANK_ESO, BANK_STA, BANK_DOB = range(5)
BANK_RECURSIVE = 1  # flags of a HOFTO tuple
BANK_TAYLOR = 2


@jit
def _hofto_transition(T: np.ndarray, hs: np.ndarray, h: float, taylor: bool) -> None:
    """T and [h, a_h2] for step h: T[i, i+j] = h^j/j! for j < s (Taylor) or I + h·shift
    (Euler): the transition matrix of the chain z_i' = z_{i+1}; a_h2 = h²/2 (Taylor) or 0."""
    s = T.shape[0]
    for i in range(s):
        for m in range(s):
            T[i, m] = 1.0 if i == m else 0.0
    terms = s if taylor else 2
    coef = 1.0
    for j in range(1, terms):
        coef *= h / j
        for i in range(s - j):
            T[i, i + j] = coef
    hs[0] = h
    hs[1] = 0.5 * h * h if taylor else 0.0


@jit
def _nan_rows(group: Any, out: np.ndarray) -> None:
    if group is not None:
        for o in literal_unroll(group):
            r = out[o[0]]
            for i in range(r.shape[0]):
                r[i] = np.nan


@jit
def _bank_hofto(
    group: Any, M: np.ndarray, a: np.ndarray, y: np.ndarray, dt: float, out: np.ndarray
) -> None:
    if group is not None:
        for entry in literal_unroll(group):  # HOFTOs of different orders: records' types
            row, rec = entry
            hofto_update(rec, y, a, dt, M, out[row])


@jit
def _bank_momentum(
    group: Any,
    M: np.ndarray,
    terms: Any,
    qd: np.ndarray,
    tau: np.ndarray,
    dt: float,
    out: np.ndarray,
) -> None:
    if group is not None:
        _, _, f, g, ct_qd, _ = terms
        for row, rec in group:
            c = rec[0]
            r = c["r"]
            momentum_update(M, qd, tau, f, g, ct_qd, c["gain"], c["p0"], c["integral"], r, dt)
            o = out[row]
            for i in range(o.shape[0]):
                o[i] = r[i]


@jit
def _bank_euler(
    group: Any, sta: bool, M: np.ndarray, a: np.ndarray, y: np.ndarray, dt: float, out: np.ndarray
) -> None:
    if group is not None:
        for row, z, gains, y_prev, sub in group:
            euler_update(z, gains, y, y_prev, a, dt / sub, sub, sta, M, out[row])


@jit
def _bank_dob(
    group: Any, terms: Any, qd: np.ndarray, tau: np.ndarray, dt: float, out: np.ndarray
) -> None:
    if group is not None:
        _, _, f, _, _, nle = terms
        for row, gj, cutoff, w, work in group:
            dob_update(gj, cutoff, w, work, qd, tau, nle, f, dt, out[row])


@jit
def bank_update(
    obs: Any,
    terms: Any,
    out: np.ndarray,
    q: np.ndarray,
    qd: np.ndarray,
    tau: np.ndarray,
    finite: bool,
    dt: float,
) -> None:
    """Every observer of ``obs`` (see above) advanced by dt [s] with the sample q, qd, tau (n,)
    and the model ``terms``, each estimate written into its row of ``out``, with the
    arithmetic of each observer's own kernel. A sample that is not ``finite`` or a non-finite
    dt: NaN in every row, no state touched."""
    hoftos, momenta, esos, stas, dobs = obs
    if not (finite and math.isfinite(dt)):
        _nan_rows(hoftos, out)
        _nan_rows(momenta, out)
        _nan_rows(esos, out)
        _nan_rows(stas, out)
        _nan_rows(dobs, out)
        return
    M, a = terms[0], terms[1]
    _bank_hofto(hoftos, M, a, q, dt, out)
    _bank_momentum(momenta, M, terms, qd, tau, dt, out)
    _bank_euler(esos, False, M, a, q, dt, out)
    _bank_euler(stas, True, M, a, q, dt, out)
    _bank_dob(dobs, terms, qd, tau, dt, out)
