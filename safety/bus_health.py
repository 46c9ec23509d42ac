"""Bus supervision: lost or stale exchanges, drive faults and drives that left Operation
enabled. Decides only: the loop reads the drive states and passes them in.

- bus loss: ``lost_cycles`` consecutive exchanges whose status is not ok or whose data is not
  fresh (lost frame, working-counter mismatch, missing TPDO, stale data);
- drive fault: an axis in Fault or Fault reaction active (the 0x603F code from the TxPDO
  goes into the event's value; it is decoded in words on the slow path);
- drive disabled: an axis that is not Operation enabled while the loop expects it to be;
  when the drive layer says that axis's safe torque off is active (``sto_of``, from its
  profile's STO source) it is the STO fault instead, naming the axis;
- brake fault: a drive fault whose 0x603F code the drive layer reads as a holding-brake
  fault (``brake_code``, from the profile) latches BRAKE as well as DRIVE_FAULT.

``sto_of`` and ``brake_code`` are asked only on the tick that found an axis out of
Operation enabled or faulted (the rare path), never on a quiet tick.

The CiA 402 state codes come from the caller (safety does not import drivers/). The tick's
compiled section 4 (hofto_hw/runtime/fused.py) runs the per-tick part: the loss streak of
:meth:`BusHealth.count` (kept here, its one place) on every exchange and
:func:`safety.kernels.drive_scan` on the drive states of good data only (stale states are not
the drives'); what the scan finds is named here, in Python (:meth:`BusHealth.report_found`), on
that rare tick. ``backend`` ``numba``/``auto`` compiles and
warms the scan, ``python`` does not. The numpy implementation it replaced is
tests/safety/reference.py; the same checks as Python calls on a monitor, for tests and the
tick's Python reference, are tests/support/reference_safety.py.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from hofto_hw import jit
from hofto_hw.jit import Backend
from safety.kernels import drive_scan
from safety.stop import Fault, StopController


class BusHealth:
    """``op_enabled``: the Operation-enabled state code; ``fault_states``: codes that count
    as a drive fault (Fault, Fault reaction active, unknown); ``backend``: python (the scan is
    not compiled), numba or auto (compiled when available, warmed here)."""

    def __init__(
        self,
        n: int,
        lost_cycles: int,
        op_enabled: int,
        fault_states: tuple[int, ...],
        backend: Backend = "python",
    ):
        self.n = n
        self.lost_cycles = int(lost_cycles)
        self.op_enabled = int(op_enabled)
        if self.op_enabled < 0:  # -1 tells the compiled scan "not expected enabled"
            raise ValueError(f"op_enabled must be a state code >= 0, got {op_enabled}")
        self.fault_min = int(min(fault_states))
        self.streak = 0
        self.lost_total = 0
        self.backend = jit.ready(backend, self._warm)
        #: True exactly when the compiled scan runs (the fused tick's condition)
        self._use_kernel = self.backend == "numba"
        #: axis -> whether its STO is active (the drive layer's reading of the process
        #: image); None: an axis out of Operation enabled is always DRIVE_DISABLED
        self.sto_of: Callable[[int], bool] | None = None
        #: (axis, 0x603F code) -> whether the code is a holding-brake fault of that drive
        self.brake_code: Callable[[int, int], bool] | None = None

    def _warm(self) -> None:
        # the drive group's state codes are uint8 (drivers/cia402/drive_group.py)
        for dtype in (np.uint8, np.int64):
            drive_scan(np.zeros(self.n, dtype=dtype), self.fault_min, self.op_enabled)

    def count(self, good: bool) -> bool:
        """The loss streak after an exchange that brought ``good`` data or not; returns
        whether BUS_LOSS is to be reported (``lost_cycles`` bad exchanges in a row; the tick
        reports it)."""
        if good:
            self.streak = 0
            return False
        self.streak += 1
        self.lost_total += 1
        return self.streak >= self.lost_cycles

    def report_found(
        self, stop: StopController, j: int, error_codes: np.ndarray, states: np.ndarray
    ) -> None:
        """What :func:`safety.kernels.drive_scan` found (its answer ``j``: an axis j < n in a
        fault state, or j - n out of Operation enabled), named and reported: on the rare tick
        the scan finds something, from the 0x603F codes ``error_codes`` and the state codes
        ``states`` (n,)."""
        if j < self.n:
            self._fault(stop, j, error_codes)
        else:
            self._disabled(stop, j - self.n, states)

    def _fault(self, stop: StopController, j: int, error_codes: np.ndarray) -> None:
        """Axis ``j`` in a fault state: DRIVE_FAULT with its 0x603F code, and BRAKE when the
        drive layer reads that code as a holding-brake fault."""
        code = int(error_codes[j])
        stop.report(Fault.DRIVE_FAULT, j, float(code))
        if self.brake_code is not None and self.brake_code(j, code):
            stop.report(Fault.BRAKE, j, float(code))

    def _disabled(self, stop: StopController, j: int, states: np.ndarray) -> None:
        """Axis ``j`` out of Operation enabled while expected in it: STO when the drive layer
        says its safe torque off is active, else DRIVE_DISABLED (with its state code)."""
        if self.sto_of is not None and self.sto_of(j):
            stop.report(Fault.STO, j, float(states[j]))
        else:
            stop.report(Fault.DRIVE_DISABLED, j, float(states[j]))
