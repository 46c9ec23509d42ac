"""The per-tick bus and limit checks as Python calls on the product's monitors
(:class:`safety.bus_health.BusHealth`, :class:`safety.limits.LimitMonitor`), each reporting
to a stop controller as it finds: what the tick's Python reference (reference_tick.py) and
the safety tests run. The product runs the same kernels (safety/kernels.py) in its compiled
section 4 (hofto_hw/runtime/fused.py), in the same order: the drive scan on good data, the
finiteness checks, ``limits_scan`` with its reports in class order, then ``limits_commit``.

The kernels run compiled when the monitor's backend is ``numba``, else as their Python
source (``hofto_hw.jit.compiled_or_python``), as the monitor was built.
"""

from __future__ import annotations

import numpy as np

from hofto_hw import jit
from safety.bus_health import BusHealth
from safety.kernels import (
    N_REPORTS,
    REPORT_JOINT,
    REPORT_VALUE,
    drive_scan,
    limits_commit,
    limits_scan,
)
from safety.limits import LIMIT_FAULTS, LimitMonitor
from safety.stop import Fault, StopController


def bus_check(
    bus: BusHealth,
    stop: StopController,
    status: int,
    fresh: bool,
    states: np.ndarray,
    error_codes: np.ndarray,
    expect_enabled: bool,
) -> bool:
    """One exchange: the loss streak (BUS_LOSS after ``lost_cycles`` bad ones in a row), then,
    on good data only (status 0 and ``fresh``), the drive states (n,): a faulted axis, else one
    out of Operation enabled while ``expect_enabled``. Returns whether the data was good."""
    good = status == 0 and fresh
    if bus.count(good):
        stop.report(Fault.BUS_LOSS, -1, float(status))
    if not good:
        return False  # stale states are not the drives': judged on fresh data only
    scan = jit.compiled_or_python(drive_scan, bus.backend)
    j = scan(states, bus.fault_min, bus.op_enabled if expect_enabled else -1)
    if j >= 0:
        bus.report_found(stop, j, error_codes, states)
    return True


def finite(stop: StopController, x: np.ndarray) -> bool:
    """NON_FINITE on the first non-finite entry of ``x`` (n,) unless all are finite; returns
    whether all were (section 4's ``_finite``)."""
    bad = ~np.isfinite(x)
    if not bad.any():
        return True
    j = int(np.argmax(bad))
    stop.report(Fault.NON_FINITE, j, float(x[j]))
    return False


def limits_check(
    monitor: LimitMonitor,
    stop: StopController,
    q: np.ndarray,
    qd: np.ndarray,
    tau: np.ndarray,
    q_cmd: np.ndarray,
    fresh: bool,
    tracking: bool,
    gap: float = 0.0,
) -> np.ndarray:
    """One tick of limit checks on the measured q, qd, tau (n,) [rad, rad/s, N·m] and last
    tick's command q_cmd (n,) [rad]: ``fresh``, the sample is new this tick; ``tracking``, the
    drives are powered and follow q_cmd; ``gap`` [s], the time between the previous fresh
    sample and this one beyond one cycle (what the rule is: safety.limits' docstring).
    Each class found is reported with its first joint, in class order; then a fresh, finite
    q becomes the previous sample. Returns the (3, n) block the kernels read: q, qd, tau's
    own rows when they are consecutive rows of one array (the drive group's), else a copy."""
    block = rows_of_one_block(q, qd, tau)
    if block is None:
        block = np.array((q, qd, tau), dtype=np.float64)
    how = int(fresh) + 2 * int(tracking)
    w = monitor._w
    scan = jit.compiled_or_python(limits_scan, monitor.backend)
    if scan(block, q_cmd, w, how, float(gap)) > 0:
        for c in range(N_REPORTS):
            j = int(w[REPORT_JOINT, c])
            if j >= 0:
                stop.report(LIMIT_FAULTS[c], j, float(w[REPORT_VALUE, c]))
    jit.compiled_or_python(limits_commit, monitor.backend)(block, w, how)
    return block


def rows_of_one_block(q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> np.ndarray | None:
    """The (3, n) view of the C-contiguous 2-D float64 array whose consecutive rows q, qd,
    tau are, or None when they are not such rows."""
    base = q.base
    if (
        not isinstance(base, np.ndarray)
        or qd.base is not base
        or tau.base is not base
        or base.ndim != 2
        or base.dtype != np.float64
        or not base.flags.c_contiguous
        or q.shape != (base.shape[1],)
    ):
        return None
    stride = base.strides[0]
    start = q.ctypes.data - base.ctypes.data
    if start % stride or qd.ctypes.data != q.ctypes.data + stride:
        return None
    if tau.ctypes.data != q.ctypes.data + 2 * stride:
        return None
    r = start // stride
    return base[r : r + 3]
