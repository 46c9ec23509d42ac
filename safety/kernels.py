"""Compiled scans of the per-tick safety checks (numba), beside the numpy reference path.

The bus and limit checks are a handful of comparisons on six joints; as numpy calls on
six-element arrays their time goes to the ~0.5 µs each call costs. These kernels only look:
they say whether anything is to be reported (and where, for the drive states). Whenever a
limit kernel sees anything to report, the caller runs its numpy reference path, so the
reports (fault class, joint, value, order) are the reference's by construction.

The backend conventions are the observers' (:mod:`hofto_hw.observers.kernels`: ``jit``,
``resolve``, warmed when the monitor is built, HOFTO_HW_NO_NUMBA=1 selects numpy).
tests/safety/test_kernels.py checks both paths give the same reports.
"""

from __future__ import annotations

import math

import numpy as np

from hofto_hw.observers.kernels import jit


@jit
def drive_scan(states: np.ndarray, fault_min: int, op_enabled: int, expect_enabled: bool) -> int:
    """The first joint j whose state code is >= ``fault_min`` (a drive fault): j; else, when
    ``expect_enabled``, the first joint not in ``op_enabled``: n + j; else -1."""
    n = states.shape[0]
    for j in range(n):
        if states[j] >= fault_min:
            return j
    if expect_enabled:
        for j in range(n):
            if states[j] != op_enabled:
                return n + j
    return -1


@jit
def limits_quiet(
    q: np.ndarray,
    qd: np.ndarray,
    tau: np.ndarray,
    q_cmd: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    velocity: np.ndarray,
    torque: np.ndarray,
    following_error: float,
    position_jump: float,
    q_prev: np.ndarray,
    have_prev: bool,
    fresh: bool,
    tracking: bool,
    gap: float,
) -> int:
    """The limit checks of :meth:`safety.limits.LimitMonitor.check` with nothing reported:
    0 when some check would report (the caller runs the reference path; nothing was
    written), 1 when none would, 2 when none would and ``q`` (fresh, all finite) was copied
    into ``q_prev``. The comparisons are the reference's (NaN compares false)."""
    n = q.shape[0]
    for j in range(n):
        x = q[j]
        if x < lower[j] or x > upper[j]:
            return 0
        if abs(qd[j]) > velocity[j]:
            return 0
        if tracking:
            if abs(tau[j]) > torque[j]:
                return 0
            if abs(q_cmd[j] - x) > following_error:
                return 0
        if fresh and have_prev:
            allow = velocity[j] * gap + position_jump if gap > 0.0 else position_jump
            if abs(x - q_prev[j]) > allow:
                return 0
    if not fresh:
        return 1
    for j in range(n):
        if not math.isfinite(q[j]):
            return 1
    for j in range(n):
        q_prev[j] = q[j]
    return 2
