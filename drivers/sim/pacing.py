"""The emulators' process priority (:func:`answer_first`), and why their simulated time is
the number of exchanges times the bus cycle, not the wall clock.

A real arm keeps moving while its controller is stalled; an emulated arm that advances one
plant tick per exchange freezes with it. Stepping the cycles of wall time since the last
exchange was tried (this branch, measured) and left out: the EtherCAT master waits one 1 ms
cycle for its frame, so stepping a stall's cycles before answering turned every stall into
a streak of lost frames; the CANopen master's SYNC leaves late within its cycle by up to a
cycle under load (12 RPDOs are sent first; that is not a missed deadline), so a gap of two
cycles between SYNCs stepped the arm two cycles while the loop's dt said one: a false
position jump at 200 Hz. The loop instead takes a stall's gap in one-cycle observer steps
(hofto_hw/runtime/fused.py, fused_tick), consistent with either view in hold.

:func:`answer_first`: the emulator process answers frames before other work (SCHED_FIFO
below the kernel's threaded IRQs when allowed, else a better nice value; no cyclic garbage
collection on the frame path). :func:`control_beside_frames`: a control thread beside the
frame path (the CANopen emulator's) one step below it: it takes the drives' lock and the
interpreter's lock, and left at normal priority it was preempted by ordinary load while
holding them, which held up the frames behind it (a priority inversion: SYNCs unanswered for
tens of ms on a loaded machine, a false following error in the loop).
"""

from __future__ import annotations

import contextlib
import gc
import os

#: SCHED_FIFO priority of an emulator process (below the kernel's threaded IRQs at 50)
RT_PRIORITY = 40


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


def control_beside_frames() -> None:
    """For a thread that serves control requests beside the frame path: SCHED_FIFO one below
    :data:`RT_PRIORITY` when allowed (never preempted by ordinary load while it holds a lock
    the frames need, never ahead of them), else as it is. Call it in that thread."""
    with contextlib.suppress(AttributeError, OSError):
        if os.sched_getscheduler(0) not in (os.SCHED_FIFO, os.SCHED_RR):
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(RT_PRIORITY - 1))
