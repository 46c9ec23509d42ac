"""Reading the flight recorder's tick ring without touching it (``Robot.stream``).

The ring (hofto_hw/recording/ring.py, inside the segment of hofto_hw/recording/shared.py)
is mapped read-only (``/dev/shm/<name>``, PROT_READ): the reader keeps its own cursor and
never writes a counter, so a slow or dead reader cannot hold the loop or the writer up. A
record is taken only if the producer cannot have started overwriting its slot while it was
copied (``head`` read after the copy is less than index + capacity); a reader that falls a
whole ring behind jumps ahead and counts what it skipped.
"""

from __future__ import annotations

import mmap
import os
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from hofto_hw.recording.record import tick_dtype
from hofto_hw.recording.ring import HEADER_BYTES
from hofto_hw.recording.shared import CONTROL_BYTES


@dataclass
class TickRecord:
    """One loop tick as the flight recorder has it (SI): ``t`` [s], ``tick``, ``q``,
    ``qd`` [rad, rad/s], ``tau``, ``q_cmd``, ``tau_ext`` {observer: (n,)} [N·m],
    ``wrench`` (6,) [N, N·m] (NaN outside drag), ``mode`` (code), ``faults`` (bit mask),
    ``skipped``: records this reader missed before this one (it fell a ring behind)."""

    t: float
    tick: int
    q: np.ndarray
    qd: np.ndarray
    tau: np.ndarray
    q_cmd: np.ndarray
    tau_ext: dict[str, np.ndarray]
    wrench: np.ndarray
    mode: int
    faults: int
    skipped: int


class RingReader:
    """A read-only view of the recorder's tick ring in segment ``shm`` (see the module
    docstring). ``capacity``: its slots; ``n`` joints, ``observers`` their names."""

    def __init__(self, shm: str, capacity: int, n: int, observers: list[str]) -> None:
        self.dtype = tick_dtype(n, len(observers))
        self.capacity = int(capacity)
        self.observers = list(observers)
        path = os.path.join("/dev/shm", shm.lstrip("/"))
        fd = os.open(path, os.O_RDONLY)
        try:
            self.map = mmap.mmap(fd, 0, prot=mmap.PROT_READ)
        finally:
            os.close(fd)
        self._ctr = np.frombuffer(self.map, "<u8", HEADER_BYTES // 8, CONTROL_BYTES)
        self._slots = np.frombuffer(
            self.map, self.dtype, self.capacity, CONTROL_BYTES + HEADER_BYTES
        )
        self.cursor = int(self._ctr[0])
        self.skipped = 0

    def head(self) -> int:
        return int(self._ctr[0])

    def read(self) -> Iterator[tuple[np.ndarray, int]]:
        """The records published since the last call, oldest first, each with the count
        skipped just before it."""
        head = self.head()
        cap = self.capacity
        while self.cursor < head:
            skipped = 0
            if head - self.cursor > cap - 16:  # about to be overwritten: jump ahead
                new = head - cap // 2
                skipped = new - self.cursor
                self.cursor = new
            i = self.cursor
            rec = self._slots[i % cap].copy()
            if self.head() >= i + cap:  # overwritten while copied: skip it
                self.cursor += 1
                self.skipped += 1
                continue
            self.cursor = i + 1
            self.skipped += skipped
            yield rec, skipped

    def latest_tick(self) -> int:
        """The loop tick of the newest record published (-1: none yet), without reading."""
        head = self.head()
        return -1 if head == 0 else int(self._slots[(head - 1) % self.capacity]["tick"])

    def record(self, rec: np.ndarray, skipped: int) -> TickRecord:
        return TickRecord(
            t=float(rec["t"]),
            tick=int(rec["tick"]),
            q=np.array(rec["q"]),
            qd=np.array(rec["qd"]),
            tau=np.array(rec["tau"]),
            q_cmd=np.array(rec["q_cmd"]),
            tau_ext={n: np.array(rec["tau_ext"][i]) for i, n in enumerate(self.observers)},
            wrench=np.array(rec["wrench"]),
            mode=int(rec["mode"]),
            faults=int(rec["faults"]),
            skipped=skipped,
        )

    def close(self) -> None:
        del self._ctr, self._slots
        try:
            self.map.close()
        except BufferError:
            pass
