"""The per-tick safety checks of the bus and the limits (numba): the one implementation.

The tick's compiled section 4 (hofto_hw/runtime/fused.py) calls them on every tick:
``drive_scan`` on the drive states, ``limits_scan`` then ``limits_commit`` on the sample in
the workspace of :class:`safety.limits.LimitMonitor`; :class:`safety.bus_health.BusHealth`
keeps the loss streak and names what the drive scan found. Compiled when the monitors are
built with backend ``numba``/``auto`` (the conventions of :mod:`hofto_hw.jit`: ``jit``,
warmed then), their own Python source otherwise (``hofto_hw.jit.compiled_or_python``;
numba's ``NUMBA_DISABLE_JIT=1`` runs every line as Python). The kernels say what is to be
reported (class, joint, value); the caller reports it. The numpy implementations they
replaced are the reference in tests/safety/reference.py; tests/safety/test_kernels.py
compares every report over thousands of random ticks, through the Python twins of the
monitors' checks in tests/support/reference_safety.py.
"""

from __future__ import annotations

import math

import numpy as np

from hofto_hw.jit import jit


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


#: rows of the limit monitor's float64 workspace (LIM_ROWS, max(n, 5)): lower, upper [rad],
#: velocity [rad/s], torque [N·m] limits, the previous fresh q [rad], a row of scalars
#: (PARAMS): following error [rad], position jump [rad], have-previous flag (0.0 / 1.0), and
#: the last scan's report per fault class (column = class below): the first joint (-1: none)
#: and its value
LOWER, UPPER, VELOCITY, TORQUE, Q_PREV, PARAMS, REPORT_JOINT, REPORT_VALUE = range(8)
LIM_ROWS = 8
FOLLOWING_ERROR, POSITION_JUMP, HAVE_PREV = 0, 1, 2
#: fault classes of the report rows, in the order they are reported: position limit (value
#: q [rad]), velocity (qd [rad/s]), torque (tau [N·m]), following error (|q_cmd - q|),
#: position jump (|q - q_prev|)
REP_POSITION, REP_VELOCITY, REP_TORQUE, REP_FOLLOWING, REP_JUMP = range(5)
N_REPORTS = 5


@jit
def _note(w: np.ndarray, c: int, j: int, value: float) -> int:
    """Record joint j and ``value`` for class c unless an earlier joint has; 1 if new."""
    if w[REPORT_JOINT, c] >= 0.0:
        return 0
    w[REPORT_JOINT, c] = j
    w[REPORT_VALUE, c] = value
    return 1


@jit
def limits_scan(sample: np.ndarray, q_cmd: np.ndarray, w: np.ndarray, how: int, gap: float) -> int:
    """The limit checks on ``sample`` (3, n) = rows q, qd, tau, the last command q_cmd (n,)
    and the workspace ``w`` (rows above): for each class the first offending joint and its
    value into the report rows; returns how many classes have one. ``how`` = fresh +
    2·tracking (one int: bools cost a compiled call more to unbox).

    What a sample is judged on: position and velocity always; torque while tracking (a
    repeated torque is still the last one the drive measured); the following error only on a
    fresh sample while tracking (a stale sample is an old position against a newer command:
    its lag is not the drive's; a run of lost samples is the bus-loss check's); jumps only on
    a fresh sample with a previous one, against ``position_jump`` plus what the velocity
    limit covers in ``gap`` [s] (a stall). NaN compares false. Writes nothing but the report
    rows."""
    n = q_cmd.shape[0]
    fresh = (how & 1) != 0
    tracking = (how & 2) != 0
    lag = fresh and tracking
    following_error = w[PARAMS, FOLLOWING_ERROR]
    position_jump = w[PARAMS, POSITION_JUMP]
    jumps = fresh and w[PARAMS, HAVE_PREV] != 0.0
    for c in range(N_REPORTS):
        w[REPORT_JOINT, c] = -1.0
        w[REPORT_VALUE, c] = 0.0
    found = 0
    for j in range(n):
        x = sample[0, j]
        if x < w[LOWER, j] or x > w[UPPER, j]:
            found += _note(w, REP_POSITION, j, x)
        v = sample[1, j]
        if abs(v) > w[VELOCITY, j]:
            found += _note(w, REP_VELOCITY, j, v)
        if tracking:
            t = sample[2, j]
            if abs(t) > w[TORQUE, j]:
                found += _note(w, REP_TORQUE, j, t)
        if lag:
            d = abs(q_cmd[j] - x)
            if d > following_error:
                found += _note(w, REP_FOLLOWING, j, d)
        if jumps:
            allow = w[VELOCITY, j] * gap + position_jump if gap > 0.0 else position_jump
            d = abs(x - w[Q_PREV, j])
            if d > allow:
                found += _note(w, REP_JUMP, j, d)
    return found


@jit
def limits_commit(sample: np.ndarray, w: np.ndarray, how: int) -> int:
    """After the checks: on a fresh sample whose q (row 0 of ``sample`` (3, n)) is all finite,
    q becomes the previous sample (Q_PREV, HAVE_PREV set): 2; else 1 (nothing written)."""
    if (how & 1) == 0:
        return 1
    n = sample.shape[1]
    for j in range(n):
        if not math.isfinite(sample[0, j]):
            return 1
    for j in range(n):
        w[Q_PREV, j] = sample[0, j]
    w[PARAMS, HAVE_PREV] = 1.0
    return 2
