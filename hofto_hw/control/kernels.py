"""The per-joint kernels of the joint motion and the friction learning: the one place of
their arithmetic.

:meth:`hofto_hw.control.joint_motion.DemoPath.evaluate`, the ramp to standstill of
:meth:`~hofto_hw.control.joint_motion.JointMotion.update` and
:meth:`hofto_hw.control.friction_residual.FrictionResidual.learn` always call these: compiled
(backend ``numba``; the tick's fused call compiles the same functions) or their own source run
by the interpreter (backend ``python``: numba's ``py_func``, as under ``NUMBA_DISABLE_JIT``).
Both take their sines, cosines, tanh and exp from the C library (the interpreter's ``math``
module and the compiled code call the same functions), so the two give the same bits.
numpy references of the same formulas live in tests/hofto_hw/control/reference.py for the
agreement tests (to the last bit where numpy's own sines are libm's, within 1e-12 where
numpy uses SIMD versions, e.g. with AVX-512).

The demo path is one call with few arguments (a compiled call pays ~0.1 µs per argument it
unboxes, tools/bench_kernel_args.py): its constants (amplitude, ω, phase, offset) are the rows
of one float64 workspace (:func:`path_workspace`).

Backend conventions are :mod:`hofto_hw.jit`'s. Kernels write
only into the arrays passed in; none allocates.
"""

from __future__ import annotations

import math

import numpy as np

from hofto_hw.jit import jit
from hofto_hw.model.kernels import coulomb_sign

#: rows of the demo path's float64 workspace (PATH_ROWS, n): amplitude [rad], ω [rad/s],
#: phase [rad], offset a·sin(phase) [rad]
AMPLITUDE, OMEGA, PHASE, OFFSET = range(4)
PATH_ROWS = 4


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
    """The demo path at ``t`` [s] into q, qd, qdd (n,): with arg = ω·t + phase,
    f = a·sin(arg) - offset, f' = a·ω·cos(arg), f'' = -a·ω²·sin(arg) and the fade-in b, b',
    b'' (:func:`hofto_hw.control.joint_motion.fade_in`): q = q0 + f·b, qd = f'·b + f·b',
    qdd = f''·b + 2·f'·b' + f·b''. ``k`` the workspace (rows above)."""
    bd2 = 2.0 * bd
    nb = -b
    for j in range(q.shape[0]):
        a = k[AMPLITUDE, j]
        w = k[OMEGA, j]
        arg = w * t + k[PHASE, j]
        if math.isinf(arg):  # NaN, as compiled; the interpreter's math.sin(inf) raises
            s = c = math.nan
        else:
            s = math.sin(arg)
            c = math.cos(arg)
        f = a * s - k[OFFSET, j]
        aw = a * w
        fd = aw * c
        q[j] = f * b + q0[j]
        qd[j] = fd * b + f * bd
        qdd[j] = aw * w * s * nb + fd * bd2 + f * bdd


def path_workspace(
    amplitude: np.ndarray, omega: np.ndarray, phase: np.ndarray, offset: np.ndarray
) -> np.ndarray:
    """The demo path's workspace (PATH_ROWS, n)."""
    k = np.zeros((PATH_ROWS, np.shape(amplitude)[0]))
    k[AMPLITUDE], k[OMEGA], k[PHASE], k[OFFSET] = amplitude, omega, phase, offset
    return k


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
def friction_feature(v: float, v_s: float) -> float:
    """The friction residual's direction feature s(v) = tanh(v / v_s) [1] of a joint
    velocity v [rad/s] (v_s > 0 [rad/s]): eq. (12)'s Coulomb feature
    (:func:`hofto_hw.model.kernels.coulomb_sign`); :func:`friction_learn` regresses on it,
    :func:`friction_features` gives it to FrictionResidual.correction."""
    return coulomb_sign(v, v_s)


@jit
def friction_features(qd: np.ndarray, v_s: float, out: np.ndarray) -> None:
    """out_j = :func:`friction_feature` (qd_j, v_s), (n,)."""
    for j in range(qd.shape[0]):
        out[j] = friction_feature(qd[j], v_s)


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
    the numpy reference (tests/hofto_hw/control/reference.py; tanh may differ from
    numpy's by one ulp)."""
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
        x1 = friction_feature(qd[j], v_s)
        x2 = qd[j]
        for r in range(3):
            xr = x0 if r == 0 else (x1 if r == 1 else x2)
            for c in range(3):
                xc = x0 if c == 0 else (x1 if c == 1 else x2)
                S[j, r, c] += (xr * xc - S[j, r, c]) * beta
            b[j, r] += (xr * tau_ext[j] - b[j, r]) * beta
    st[2] += h
    return True
