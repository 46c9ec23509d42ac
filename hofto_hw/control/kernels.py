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
