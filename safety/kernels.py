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
def drive_scan(states: np.ndarray, fault_min: int, op_enabled: int) -> int:
    """The first joint j whose state code is >= ``fault_min`` (a drive fault): j; else, when
    ``op_enabled`` >= 0 (the caller expects the drives enabled; -1 when it does not), the
    first joint not in ``op_enabled``: n + j; else -1. (No bool argument: a bool costs a
    compiled call more to unbox than an int.)"""
    n = states.shape[0]
    for j in range(n):
        if states[j] >= fault_min:
            return j
    if op_enabled >= 0:
        for j in range(n):
            if states[j] != op_enabled:
                return n + j
    return -1


#: rows of the limit monitor's float64 workspace (LIM_ROWS, max(n, 3)): lower, upper [rad],
#: velocity [rad/s], torque [N·m] limits, the previous fresh q [rad], and a row of scalars
#: (PARAMS): following error [rad], position jump [rad], have-previous flag (0.0 / 1.0)
LOWER, UPPER, VELOCITY, TORQUE, Q_PREV, PARAMS = range(6)
LIM_ROWS = 6
FOLLOWING_ERROR, POSITION_JUMP, HAVE_PREV = 0, 1, 2


@jit
def limits_quiet(sample: np.ndarray, q_cmd: np.ndarray, w: np.ndarray, how: int, gap: float) -> int:
    """The limit checks of :meth:`safety.limits.LimitMonitor.check` with nothing reported, on
    ``sample`` (3, n) = rows q, qd, tau and the workspace ``w`` (rows above); ``how`` = fresh
    + 2·tracking (one int: bools cost a compiled call more to unbox): 0 when some check
    would report (the caller runs the reference path; nothing was written), 1 when none
    would, 2 when none would and ``q`` (fresh, all finite) was copied into the Q_PREV row
    (HAVE_PREV set). The comparisons are the reference's (NaN compares false)."""
    n = q_cmd.shape[0]
    fresh = (how & 1) != 0
    tracking = (how & 2) != 0
    following_error = w[PARAMS, FOLLOWING_ERROR]
    position_jump = w[PARAMS, POSITION_JUMP]
    jumps = fresh and w[PARAMS, HAVE_PREV] != 0.0
    for j in range(n):
        x = sample[0, j]
        if x < w[LOWER, j] or x > w[UPPER, j]:
            return 0
        if abs(sample[1, j]) > w[VELOCITY, j]:
            return 0
        if tracking:
            if abs(sample[2, j]) > w[TORQUE, j]:
                return 0
            if abs(q_cmd[j] - x) > following_error:
                return 0
        if jumps:
            allow = w[VELOCITY, j] * gap + position_jump if gap > 0.0 else position_jump
            if abs(x - w[Q_PREV, j]) > allow:
                return 0
    if not fresh:
        return 1
    for j in range(n):
        if not math.isfinite(sample[0, j]):
            return 1
    for j in range(n):
        w[Q_PREV, j] = sample[0, j]
    w[PARAMS, HAVE_PREV] = 1.0
    return 2
