"""Compiled per-joint kernels of the joint motion (numba), beside the numpy reference path.

:meth:`hofto_hw.control.joint_motion.DemoPath.evaluate` and the ramp to standstill of
:meth:`~hofto_hw.control.joint_motion.JointMotion.update` are some twenty numpy calls on six
joints each; these kernels do the same IEEE operations in the same order, one call each. The
sines and cosines stay numpy's (``np.sin``/``np.cos`` may round differently from libm), so
both paths give bit-identical references; tests/hofto_hw/control/test_kernels.py checks it.

Backend conventions are the observers' (:mod:`hofto_hw.observers.kernels`). Kernels write
only into the arrays passed in; none allocates.
"""

from __future__ import annotations

import math

import numpy as np

from hofto_hw.observers.kernels import jit


@jit
def path_arg(w: np.ndarray, phi: np.ndarray, t: float, arg: np.ndarray) -> None:
    """arg = w·t + phi (n,)."""
    for j in range(arg.shape[0]):
        arg[j] = w[j] * t + phi[j]


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
        f = a[j] * s[j] - offset[j]
        aw = a[j] * w[j]
        fd = aw * c[j]
        qdd[j] = aw * w[j] * s[j] * nb + fd * bd2 + f * bdd
        qd[j] = fd * b + f * bd
        q[j] = f * b + q0[j]


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
