"""The shared-memory segment between the loop and the writer process: a control block and
three rings (tick, event, diagnostics records of :mod:`hofto_hw.recording.record`).

Control block: u64 words, each written by one side only (``stop`` by the owner, the rest by
the writer), so neither side needs a lock.
"""

from __future__ import annotations

from dataclasses import dataclass
from multiprocessing import shared_memory

import numpy as np

from hofto_hw.recording.record import DIAG_DTYPE, EVENT_DTYPE
from hofto_hw.recording.ring import Ring, ring_nbytes

CONTROL_BYTES = 256

#: control words (index into the u64 view); the owner writes STOP, the writer the others.
#: INDEX: rotation index of the open file; FLUSHED: records whose messages are in closed
#: chunks handed to the kernel (they survive a SIGKILL).
(STOP, PID, HEARTBEAT, BYTES, RECORDS, ERRORS, FAILING, FILES, LOST, STATE, FLUSHED,
 INDEX) = range(12)  # fmt: skip

#: writer states in the STATE word
STARTING, RUNNING, FAILED, FINISHED = 0, 1, 2, 3
STATE_NAMES = {STARTING: "starting", RUNNING: "running", FAILED: "failed", FINISHED: "finished"}


@dataclass(frozen=True)
class Capacities:
    """Slots per ring (powers of two). Ticks: 4096 = 4 s at 1 kHz of writer stall."""

    tick: int = 4096
    event: int = 256
    diag: int = 256


class SharedBlock:
    """The segment seen from one side: ``control`` (u64 words) and the rings ``ticks``,
    ``events``, ``diags``. ``create=True`` makes (and later unlinks) the segment."""

    def __init__(
        self,
        tick_dtype: np.dtype,
        caps: Capacities,
        *,
        name: str | None = None,
        create: bool = False,
    ) -> None:
        sizes = [
            ring_nbytes(tick_dtype, caps.tick),
            ring_nbytes(EVENT_DTYPE, caps.event),
            ring_nbytes(DIAG_DTYPE, caps.diag),
        ]
        total = CONTROL_BYTES + sum(sizes)
        if create:
            self.shm = shared_memory.SharedMemory(create=True, size=total)
        else:
            self.shm = _attach(name or "")
        self.owner = create
        buf = self.shm.buf
        self.control = np.ndarray((CONTROL_BYTES // 8,), dtype="<u8", buffer=buf)
        if create:
            # touch every page now: the loop's first pushes must not page-fault
            np.ndarray((total,), dtype=np.uint8, buffer=buf)[:] = 0
        off = CONTROL_BYTES
        self.ticks = Ring(buf, off, tick_dtype, caps.tick, init=create)
        off += sizes[0]
        self.events = Ring(buf, off, EVENT_DTYPE, caps.event, init=create)
        off += sizes[1]
        self.diags = Ring(buf, off, DIAG_DTYPE, caps.diag, init=create)

    @property
    def name(self) -> str:
        return self.shm.name

    def close(self) -> None:
        """Drop this side's views; the creator also unlinks the segment."""
        for attr in ("control", "ticks", "events", "diags"):
            self.__dict__.pop(attr, None)
        try:
            self.shm.close()
        except BufferError:  # a caller still holds a view: leave the mapping to exit
            pass
        if self.owner:
            try:
                self.shm.unlink()
            except FileNotFoundError:
                pass


def _attach(name: str) -> shared_memory.SharedMemory:
    """Attach to the owner's segment without letting this process's resource tracker own it
    (before Python 3.13 the tracker would unlink the owner's segment when we exit)."""
    try:
        return shared_memory.SharedMemory(name=name, track=False)  # type: ignore[call-arg]
    except TypeError:  # Python < 3.13
        from multiprocessing import resource_tracker

        shm = shared_memory.SharedMemory(name=name)
        resource_tracker.unregister(shm._name, "shared_memory")  # type: ignore[attr-defined]
        return shm
