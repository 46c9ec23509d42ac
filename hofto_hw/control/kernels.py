"""Compiled per-joint kernels of the joint motion (numba), beside the numpy reference path.

:meth:`hofto_hw.control.joint_motion.DemoPath.evaluate` and the ramp to standstill of
:meth:`~hofto_hw.control.joint_motion.JointMotion.update` are some twenty numpy calls on six
joints each; these kernels do the same IEEE operations in the same order, one call each, so
both paths give bit-identical references; tests/hofto_hw/control/test_kernels.py checks it.

The demo path is one call with few arguments (a compiled call pays ~0.1 µs per argument it
unboxes, tools/bench_kernel_args.py): its constants (amplitude, ω, phase, offset) are the rows
of one float64 workspace (:func:`path_workspace`), and the sines and cosines are computed in
the kernel (libm's) when libm's ``sin``/``cos`` give numpy's bits on this machine (numpy may
use its own SIMD versions, e.g. with AVX-512; :func:`libm_trig_is_numpys` checks once per
process). Where they do not, :func:`path_evaluator` returns the same call made of the kernels
around numpy's ``np.sin``/``np.cos`` (four calls), so the result stays numpy's bit for bit.

Backend conventions are the observers' (:mod:`hofto_hw.observers.kernels`). Kernels write
only into the arrays passed in; none allocates.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from hofto_hw.observers.kernels import jit

#: rows of the demo path's float64 workspace (PATH_ROWS, n): amplitude [rad], ω [rad/s],
#: phase [rad], offset a·sin(phase) [rad]; then scratch rows sin, cos and the argument
#: (used when the sines are numpy's, see :func:`path_evaluator`)
AMPLITUDE, OMEGA, PHASE, OFFSET, SIN, COS, ARG = range(7)
PATH_ROWS = 7


@jit
def path_arg(w: np.ndarray, phi: np.ndarray, t: float, arg: np.ndarray) -> None:
    """arg = w·t + phi (n,)."""
    for j in range(arg.shape[0]):
        arg[j] = w[j] * t + phi[j]


@jit
def _blend_joint(
    a: float,
    w: float,
    offset: float,
    s: float,
    c: float,
    b: float,
    bd: float,
    bdd: float,
    bd2: float,
    nb: float,
    q0: float,
) -> tuple[float, float, float]:
    """One joint of the demo path: q, qd, qdd from amplitude, ω, offset, s = sin(arg),
    c = cos(arg), the fade-in b, b', b'' (bd2 = 2·b', nb = -b) and the start q0, in the
    operation order of the numpy reference."""
    f = a * s - offset
    aw = a * w
    fd = aw * c
    return f * b + q0, fd * b + f * bd, aw * w * s * nb + fd * bd2 + f * bdd


@jit
def path_blend(
    a: np.ndarray,
    w: np.ndarray,
    offset: np.ndarray,
    s: np.ndarray,
    c: np.ndarray,
    b: float,
    bd: float,
    bdd: float,
    q0: np.ndarray,
    q: np.ndarray,
    qd: np.ndarray,
    qdd: np.ndarray,
) -> None:
    """q, qd, qdd of the demo path from s = sin(arg), c = cos(arg) and the fade-in b, b', b''
    (the operation order of the numpy reference)."""
    bd2 = 2.0 * bd
    nb = -b
    for j in range(q.shape[0]):
        q[j], qd[j], qdd[j] = _blend_joint(
            a[j], w[j], offset[j], s[j], c[j], b, bd, bdd, bd2, nb, q0[j]
        )


@jit
def path_eval(
    k: np.ndarray,
    t: float,
    b: float,
    bd: float,
    bdd: float,
    q0: np.ndarray,
    q: np.ndarray,
    qd: np.ndarray,
    qdd: np.ndarray,
) -> None:
    """The demo path at ``t`` [s] in one call: arg = ω·t + phase, s = sin(arg), c = cos(arg)
    (libm's), then :func:`path_blend`'s arithmetic with the fade-in b, b', b'' into q, qd,
    qdd (n,); ``k`` the workspace (rows above)."""
    bd2 = 2.0 * bd
    nb = -b
    for j in range(q.shape[0]):
        w = k[OMEGA, j]
        arg = w * t + k[PHASE, j]
        q[j], qd[j], qdd[j] = _blend_joint(
            k[AMPLITUDE, j],
            w,
            k[OFFSET, j],
            math.sin(arg),
            math.cos(arg),
            b,
            bd,
            bdd,
            bd2,
            nb,
            q0[j],
        )


def _path_eval_numpy_trig(
    k: np.ndarray,
    t: float,
    b: float,
    bd: float,
    bdd: float,
    q0: np.ndarray,
    q: np.ndarray,
    qd: np.ndarray,
    qdd: np.ndarray,
) -> None:
    """:func:`path_eval` with numpy's sines and cosines (four calls; the scratch rows of k)."""
    s, c, arg = k[SIN], k[COS], k[ARG]
    path_arg(k[OMEGA], k[PHASE], t, arg)
    np.sin(arg, out=s)
    np.cos(arg, out=c)
    path_blend(k[AMPLITUDE], k[OMEGA], k[OFFSET], s, c, b, bd, bdd, q0, q, qd, qdd)


def path_workspace(
    amplitude: np.ndarray, omega: np.ndarray, phase: np.ndarray, offset: np.ndarray
) -> np.ndarray:
    """The demo path's workspace (PATH_ROWS, n) with its constant rows filled."""
    k = np.zeros((PATH_ROWS, np.shape(amplitude)[0]))
    k[AMPLITUDE], k[OMEGA], k[PHASE], k[OFFSET] = amplitude, omega, phase, offset
    return k


@jit
def _libm_sin_cos(x: np.ndarray, s: np.ndarray, c: np.ndarray) -> None:
    for i in range(x.shape[0]):
        if math.isfinite(x[i]):
            s[i] = math.sin(x[i])
            c[i] = math.cos(x[i])
        else:  # NaN, as libm and numpy give; Python's math.sin(inf) raises (NUMBA_DISABLE_JIT)
            s[i] = c[i] = math.nan


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    """Same values and signs of zero, NaN where NaN (any NaN payload)."""
    nan = np.isnan(a)
    if not np.array_equal(nan, np.isnan(b)):
        return False
    return bool(np.array_equal(a[~nan].view(np.int64), b[~nan].view(np.int64)))


_TRIG_SAME: list[bool] = []  # the check's answer, once per process


def libm_trig_is_numpys() -> bool:
    """True when the compiled ``math.sin``/``math.cos`` give ``np.sin``/``np.cos``'s bits on
    200,000 arguments (uniform over ±10 and log-uniform up to ±1e6 rad: the demo path's
    ω·t + phase over hours of running), signed zeros and non-finite values included."""
    if not _TRIG_SAME:
        rng = np.random.default_rng(20261123)
        x = np.concatenate(
            [
                rng.uniform(-10.0, 10.0, 100_000),
                rng.choice([-1.0, 1.0], 100_000) * 10.0 ** rng.uniform(-8.0, 6.0, 100_000),
                [0.0, -0.0, np.pi, -np.pi, 0.5 * np.pi, np.inf, -np.inf, np.nan],
            ]
        )
        s, c = np.empty_like(x), np.empty_like(x)
        _libm_sin_cos(x, s, c)
        with np.errstate(invalid="ignore"):
            same = _same_bits(s, np.sin(x)) and _same_bits(c, np.cos(x))
        _TRIG_SAME.append(bool(same))
    return _TRIG_SAME[0]


def path_evaluator() -> Callable[..., None]:
    """The compiled demo-path call of this machine, ``(k, t, b, bd, bdd, q0, q, qd, qdd)``:
    :func:`path_eval` (one call) when libm's sines are numpy's here, else the same
    arithmetic around numpy's ``np.sin``/``np.cos``. Compiles the check's kernel (call it
    at start-up, not in the tick)."""
    return path_eval if libm_trig_is_numpys() else _path_eval_numpy_trig


@jit
def ramp_step(accel: np.ndarray, dt: float, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> bool:
    """One tick of the ramp to standstill at ``accel`` [rad/s²]; True when qd is all zero
    afterwards (then qdd is zeroed, as the reference does)."""
    k = -1.0 / dt
    moving = False
    n = q.shape[0]
    for j in range(n):
        v = qd[j]
        a = abs(v)
        step = accel[j] * dt
        if math.isnan(a) or math.isnan(step):
            step = math.nan  # np.minimum propagates NaN
        elif a < step:
            step = a
        if v > 0.0:
            sg = 1.0
        elif v < 0.0:
            sg = -1.0
        elif v == 0.0:
            sg = 0.0  # np.sign(-0.0) is +0.0
        else:
            sg = v  # NaN
        step *= sg
        v -= step
        qd[j] = v
        qdd[j] = step * k
        q[j] += v * dt
        if v != 0.0:
            moving = True
    if not moving:
        for j in range(n):
            qdd[j] = 0.0
    return not moving


@jit
def friction_learn(
    qd: np.ndarray,
    tau_ext: np.ndarray,
    dt: float,
    v_s: float,
    time_constant: float,
    min_speed: float,
    every: int,
    S: np.ndarray,
    b: np.ndarray,
    st: np.ndarray,
) -> bool:
    """:meth:`hofto_hw.control.friction_residual.FrictionResidual.learn` in one call:
    ``st`` = [count, pending time [s], seconds learned [s]] updated in place, ``S`` (n, 3, 3)
    and ``b`` (n, 3) the exponentially weighted sums. Same operations in the same order as
    the numpy path (tanh may differ from numpy's by one ulp)."""
    n = qd.shape[0]
    fastest = 0.0
    for j in range(n):
        a = abs(qd[j])
        if a > fastest:
            fastest = a
    if fastest < min_speed:
        return False
    st[1] += dt
    st[0] += 1.0
    if st[0] < every:
        return True
    st[0] = 0.0
    h = st[1]
    st[1] = 0.0
    beta = 1.0 - math.exp(-h / time_constant)
    for j in range(n):
        x0 = 1.0
        x1 = math.tanh(qd[j] / v_s)
        x2 = qd[j]
        for r in range(3):
            xr = x0 if r == 0 else (x1 if r == 1 else x2)
            for c in range(3):
                xc = x0 if c == 0 else (x1 if c == 1 else x2)
                S[j, r, c] += (xr * xc - S[j, r, c]) * beta
            b[j, r] += (xr * tau_ext[j] - b[j, r]) * beta
    st[2] += h
    return True
