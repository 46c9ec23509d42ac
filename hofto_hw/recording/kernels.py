"""Compiled fill of the tick record (numba); the same source runs as Python without numba.

Filling the record field by field costs a numpy call (~0.1-0.5 µs) per field; this kernel
writes every per-tick field of a record in one call (the sample as one (3, n) array, the
tick's copy of the command riding along; scalars packed into small arrays measured slower:
each element written from Python costs more than an argument). ``rec`` is the tick record
seen as a one-element array (``new_record(...).reshape(1)``: a view, the same memory). Backend
conventions are :mod:`hofto_hw.jit`'s; the tick warms the
kernel when built. tests/hofto_hw/runtime/test_record_kernel.py checks it against a
field-by-field numpy reference kept there.
"""

from __future__ import annotations

import numpy as np

from hofto_hw.jit import jit


@jit
def fill_tick(
    rec: np.ndarray,
    sample: np.ndarray,
    q_cmd: np.ndarray,
    tau_ext: np.ndarray,
    q_sent: np.ndarray,
    t: float,
    tick: int,
    mode: int,
    faults: int,
    bus_status: int,
    wakeup_us: float,
    compute_us: float,
    sample_dt: float,
) -> None:
    """Write t [s], tick, the sample q, qd, tau (rows of ``sample`` (3, n)), q_cmd (n,),
    tau_ext (k, n), mode, faults (bit mask), bus_status, the loop timings [µs] and the
    observers' sample_dt [s] into ``rec[0]``; and ``q_sent[:] = q_cmd`` (n,) (the tick's
    copy of the command just sent, in the same pass)."""
    r = rec[0]
    r["t"] = t
    r["tick"] = tick
    for j in range(q_cmd.shape[0]):
        r["q"][j] = sample[0, j]
        r["qd"][j] = sample[1, j]
        r["tau"][j] = sample[2, j]
        r["q_cmd"][j] = q_cmd[j]
        q_sent[j] = q_cmd[j]
    for i in range(tau_ext.shape[0]):
        for j in range(tau_ext.shape[1]):
            r["tau_ext"][i, j] = tau_ext[i, j]
    r["mode"] = mode
    r["faults"] = faults
    r["bus_status"] = bus_status
    r["wakeup_us"] = wakeup_us
    r["compute_us"] = compute_us
    r["sample_dt"] = sample_dt
