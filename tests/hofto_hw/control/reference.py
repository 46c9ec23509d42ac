"""numpy references of the joint-motion and friction-learning kernels (hofto_hw/control/
kernels.py), for the agreement tests only: the product always runs the kernels (compiled, or
their own source run by the interpreter). Written independently of the kernels, as vector
calls over the joints: the demo path of hofto_hw.control.joint_motion.DemoPath, the ramp to
standstill of JointMotion, and FrictionResidual.learn's weighted sums.
"""

from __future__ import annotations

import math

import numpy as np

from hofto_hw.control.joint_motion import fade_in


def demo_path(
    a: np.ndarray,
    w: np.ndarray,
    phi: np.ndarray,
    ramp: float,
    t: float,
    q0: np.ndarray,
    q: np.ndarray,
    qd: np.ndarray,
    qdd: np.ndarray,
) -> None:
    """q = q0 + (a·sin(w·t + phi) - a·sin(phi))·s(t) and its derivatives into q, qd, qdd (n,)
    (s the quintic fade-in over ``ramp`` [s]); numpy's sines."""
    b, bd, bdd = fade_in(t, ramp)
    arg = w * t + phi
    s, c = np.sin(arg), np.cos(arg)
    f = a * s - a * np.sin(phi)  # f = a·sin - offset
    fd = a * w * c  # f' = a·w·cos; f'' = -a·w²·sin
    q[:] = f * b + q0
    qd[:] = fd * b + f * bd
    qdd[:] = a * w * w * s * -b + fd * (2.0 * bd) + f * bdd


def ramp_step(accel: np.ndarray, dt: float, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> bool:
    """One tick of the ramp to standstill at ``accel`` [rad/s²] (n,), in place; True when qd
    is all zero afterwards (then qdd is zeroed)."""
    step = np.minimum(accel * dt, np.abs(qd)) * np.sign(qd)
    qd -= step
    np.multiply(step, -1.0 / dt, out=qdd)
    q += qd * dt
    if qd.any():
        return False
    qdd.fill(0.0)
    return True


class FrictionLearning:
    """FrictionResidual.learn's sums S (n, 3, 3), b (n, 3) over x = (1, tanh(qd/v_s), qd),
    exponentially weighted by the time learned from (one moving sample in ``every``)."""

    def __init__(self, n: int, v_s: float, time_constant: float, min_speed: float, every: int):
        self.v_s, self.tau, self.min_speed, self.every = v_s, time_constant, min_speed, every
        self.S = np.zeros((n, 3, 3))
        self.b = np.zeros((n, 3))
        self.count = 0
        self.pending = 0.0
        self.seconds = 0.0

    def learn(self, qd: np.ndarray, tau_ext: np.ndarray, dt: float) -> bool:
        if np.abs(qd).max() < self.min_speed:
            return False
        self.pending += dt
        self.count += 1
        if self.count < self.every:
            return True
        self.count = 0
        h, self.pending = self.pending, 0.0
        x = np.stack([np.ones_like(qd), np.tanh(qd / self.v_s), qd], axis=1)  # (n, 3)
        beta = 1.0 - math.exp(-h / self.tau)
        self.S += (x[:, :, None] * x[:, None, :] - self.S) * beta
        self.b += (x * tau_ext[:, None] - self.b) * beta
        self.seconds += h
        return True


def friction_correction(
    coef: np.ndarray, v_s: float, limit: float, friction: np.ndarray, qd: np.ndarray
) -> np.ndarray:
    """FrictionResidual.correction as numpy calls: c_s·tanh(qd/v_s) + c_v·qd (n,) [N·m],
    clipped to ±limit·|friction| (the model's friction at qd, (n,) [N·m])."""
    out = coef[:, 1] * np.tanh(qd / v_s) + coef[:, 2] * qd
    bound = limit * np.abs(friction)
    return np.maximum(np.minimum(out, bound), -bound)
