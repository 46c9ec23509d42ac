"""How an emulator keeps up with the wall clock, and its process priority.

A real arm keeps moving while its controller is stalled; an emulated arm that advances
exactly one plant tick per exchange froze with the controller, so after a controller stall
of 100 ms the data had moved 5 ms at 200 Hz while the controller's clock said 100 ms.
:class:`WallCycles` tells an emulator how many plant ticks an exchange stands for: the whole
bus cycles of wall time since the last one (at least one; a gap longer than ``limit`` is a
pause of the cyclic exchange, such as start-up, and counts one). The CANopen emulator steps
those cycles at the SYNC, the last RPDOs held, before it samples the TPDOs (a few plant
steps of ~0.2-0.5 ms against a 4 ms TPDO deadline at 200 Hz). The EtherCAT emulator does
not: its master waits one 1 ms cycle for the frame, so stepping a stall's cycles before
answering would turn every stall into a streak of lost frames.

:func:`answer_first`: the emulator process answers frames before other work (SCHED_FIFO
below the kernel's threaded IRQs when allowed, else a better nice value; no cyclic garbage
collection on the frame path).
"""

from __future__ import annotations

import contextlib
import gc
import math
import os
import time

#: SCHED_FIFO priority of an emulator process (below the kernel's threaded IRQs at 50)
RT_PRIORITY = 40


class WallCycles:
    """Plant ticks due per exchange by the wall clock; ``period`` [s] the bus cycle,
    ``limit`` [s] the longest gap caught up (host stalls of up to ~110 ms were measured on
    the shared VM)."""

    def __init__(self, period: float, limit: float = 0.15) -> None:
        self.period = float(period)
        self.max_cycles = max(1, int(limit / self.period))
        self.anchor = -1.0  # wall time the plant's state belongs to [s, monotonic]
        self.caught_up = 0  # ticks stepped beyond one per exchange, in total
        self.capped = 0  # exchanges after a gap longer than ``limit``

    def due(self, now: float | None = None) -> int:
        """Plant ticks for an exchange at ``now`` (default: time.monotonic())."""
        now = time.monotonic() if now is None else now
        if self.anchor < 0.0:
            self.anchor = now
            return 1
        n = math.floor((now - self.anchor) / self.period)
        if n > self.max_cycles:
            # not a stall but a pause of the cyclic exchange (start-up, SDO phases): the
            # emulated world waited; catching it up would only delay the next answers
            self.capped += 1
            self.anchor = now
            n = 1
        else:
            n = max(1, n)
            # never ahead of the wall clock: an early frame does not buy future ticks
            self.anchor = min(self.anchor + n * self.period, now)
        self.caught_up += n - 1
        return n

    def restart(self) -> None:
        """Forget the anchor (the next exchange counts one tick)."""
        self.anchor = -1.0


def answer_first() -> None:
    """Raise this process to SCHED_FIFO :data:`RT_PRIORITY` when allowed (its loops block
    in select/recv, so they never spin), else to nice -10; freeze the objects made so far
    out of the garbage collector and turn cyclic collection off (the caller collects
    between control requests)."""
    try:
        if os.sched_getscheduler(0) not in (os.SCHED_FIFO, os.SCHED_RR):  # keep a chrt choice
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(RT_PRIORITY))
    except (AttributeError, OSError):
        with contextlib.suppress(OSError):
            os.nice(-10)
    gc.collect()
    gc.freeze()
    gc.disable()
