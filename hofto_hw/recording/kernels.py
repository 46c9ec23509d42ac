"""Compiled fill of the tick record (numba), beside the numpy reference in
:meth:`hofto_hw.runtime.tick.Tick._record`.

Filling the record field by field costs a numpy call (~0.1-0.5 µs) per field; this kernel
writes every per-tick field of a record in one call. ``rec`` is the tick record seen as a
one-element array (``new_record(...).reshape(1)``: a view, the same memory). Backend
conventions are the observers' (:mod:`hofto_hw.observers.kernels`); the tick warms the
kernel when built. tests/hofto_hw/runtime/test_record_kernel.py checks both fills give the
same bytes.
"""

from __future__ import annotations

import numpy as np

from hofto_hw.observers.kernels import jit


@jit
def fill_tick(
    rec: np.ndarray,
    t: float,
    tick: int,
    q: np.ndarray,
    qd: np.ndarray,
    tau: np.ndarray,
    q_cmd: np.ndarray,
    tau_ext: np.ndarray,
    mode: int,
    faults: int,
    bus_status: int,
    wakeup_us: float,
    compute_us: float,
) -> None:
    """Write t [s], tick, q, qd, tau, q_cmd (n,), tau_ext (k, n), mode, faults (bit mask),
    bus_status and the loop timings [µs] into ``rec[0]``."""
    r = rec[0]
    r.t = t
    r.tick = tick
    for j in range(q.shape[0]):
        r.q[j] = q[j]
        r.qd[j] = qd[j]
        r.tau[j] = tau[j]
        r.q_cmd[j] = q_cmd[j]
    for i in range(tau_ext.shape[0]):
        for j in range(tau_ext.shape[1]):
            r.tau_ext[i, j] = tau_ext[i, j]
    r.mode = mode
    r.faults = faults
    r.bus_status = bus_status
    r.wakeup_us = wakeup_us
    r.compute_us = compute_us
