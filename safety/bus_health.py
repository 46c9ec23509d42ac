"""Bus supervision: lost or stale exchanges, drive faults and drives that left Operation
enabled. Decides only: the loop reads the drive states and passes them in.

- bus loss: ``lost_cycles`` consecutive exchanges whose status is not ok or whose data is not
  fresh (lost frame, working-counter mismatch, missing TPDO, stale data);
- drive fault: an axis in Fault or Fault reaction active (the 0x603F code from the TxPDO
  goes into the event's value; it is decoded in words on the slow path);
- drive disabled: an axis that is not Operation enabled while the loop expects it to be.

The CiA 402 state codes come from the caller (safety does not import drivers/).
Allocation-free per tick. ``backend``: ``numpy`` (the reference) or the compiled drive-state
scan of :mod:`safety.kernels` (``numba``/``auto``, the observers' conventions).
"""

from __future__ import annotations

import numpy as np

from hofto_hw.observers import kernels
from hofto_hw.observers.kernels import Backend
from safety.kernels import drive_scan
from safety.stop import Fault, StopController


class BusHealth:
    """``op_enabled``: the Operation-enabled state code; ``fault_states``: codes that count
    as a drive fault (Fault, Fault reaction active, unknown); ``backend``: numpy (the
    reference), numba or auto (compiled when available, warmed here)."""

    def __init__(
        self,
        n: int,
        lost_cycles: int,
        op_enabled: int,
        fault_states: tuple[int, ...],
        backend: Backend = "numpy",
    ):
        self.n = n
        self.lost_cycles = int(lost_cycles)
        self.op_enabled = int(op_enabled)
        if self.op_enabled < 0:  # -1 tells the compiled scan "not expected enabled"
            raise ValueError(f"op_enabled must be a state code >= 0, got {op_enabled}")
        self.fault_min = int(min(fault_states))
        self.streak = 0
        self.lost_total = 0
        self._m = np.zeros(n, dtype=bool)
        self.backend = kernels.ready(backend, self._warm)
        self._use_kernel = self.backend == "numba"

    def _warm(self) -> None:
        # the drive group's state codes are uint8 (drivers/cia402/drive_group.py)
        for dtype in (np.uint8, np.int64):
            drive_scan(np.zeros(self.n, dtype=dtype), self.fault_min, self.op_enabled)

    def check(
        self,
        stop: StopController,
        status: int,
        fresh: bool,
        states: np.ndarray,
        error_codes: np.ndarray,
        expect_enabled: bool,
    ) -> bool:
        """One tick; returns whether this exchange brought good data."""
        good = status == 0 and fresh
        if good:
            self.streak = 0
        else:
            self.streak += 1
            self.lost_total += 1
            if self.streak >= self.lost_cycles:
                stop.report(Fault.BUS_LOSS, -1, float(status))
            return False  # states are stale: judge the drives on fresh data only
        if self._use_kernel:
            j = drive_scan(states, self.fault_min, self.op_enabled if expect_enabled else -1)
            if j >= 0:
                n = self.n
                if j < n:
                    stop.report(Fault.DRIVE_FAULT, j, float(error_codes[j]))
                else:
                    stop.report(Fault.DRIVE_DISABLED, j - n, float(states[j - n]))
            return True
        m = self._m
        np.greater_equal(states, self.fault_min, out=m)
        if m.any():
            j = int(np.argmax(m))
            stop.report(Fault.DRIVE_FAULT, j, float(error_codes[j]))
        elif expect_enabled:
            np.not_equal(states, self.op_enabled, out=m)
            if m.any():
                j = int(np.argmax(m))
                stop.report(Fault.DRIVE_DISABLED, j, float(states[j]))
        return True
