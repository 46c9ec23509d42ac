"""A single-producer / single-consumer ring of fixed-size records in shared memory.

The loop (producer) copies a record into the next free slot and publishes it by advancing
``head``; the writer process (consumer) copies the slots between ``tail`` and ``head`` out
and advances ``tail``. Each counter has exactly one writer, so no lock is needed: the
producer never waits, and a full ring drops the record and counts it in ``dropped``.

Layout at ``offset`` in a shared buffer (all counters little-endian u64, each on its own
64-byte cache line so the two processes do not share one):

- byte 0: ``head`` — records published (producer-owned);
- byte 8: ``dropped`` — records refused because the ring was full (producer-owned);
- byte 64: ``tail`` — records consumed (consumer-owned);
- byte 128: ``capacity`` slots of ``dtype.itemsize`` bytes.

Ordering: the producer writes the slot before it stores ``head``, the consumer reads ``head``
before it reads the slots and stores ``tail`` after; on x86-64 and with CPython's
aligned 8-byte numpy stores this is enough (stores are not reordered with stores, loads not
with loads). On weakly ordered CPUs (ARM) the CPython eval loop between the two stores acts
as a barrier in practice; a C extension with explicit fences would be the strict version.
"""

from __future__ import annotations

import numpy as np

HEADER_BYTES = 128
_HEAD, _DROPPED, _TAIL = 0, 1, 8  # u64 word indices in the header


def ring_nbytes(dtype: np.dtype, capacity: int) -> int:
    """Bytes one ring of ``capacity`` slots of ``dtype`` needs (header included)."""
    return HEADER_BYTES + int(capacity) * np.dtype(dtype).itemsize


class Ring:
    """One ring inside ``buf`` (a writable buffer, e.g. ``SharedMemory.buf``) at ``offset``.

    Both sides construct a Ring over the same bytes; ``init=True`` (the creator, once)
    zeroes the counters. :meth:`push` is the producer's only method, :meth:`drain` the
    consumer's. ``capacity`` must be a power of two (the slot index is a mask).
    """

    def __init__(
        self, buf: memoryview, offset: int, dtype: np.dtype, capacity: int, *, init: bool = False
    ) -> None:
        capacity = int(capacity)
        if capacity < 2 or capacity & (capacity - 1):
            raise ValueError(f"ring capacity must be a power of two >= 2, got {capacity}")
        self.dtype = np.dtype(dtype)
        self.capacity = capacity
        self._mask = capacity - 1
        self._ctr = np.ndarray((HEADER_BYTES // 8,), dtype="<u8", buffer=buf, offset=offset)
        self._slots = np.ndarray(
            (capacity,), dtype=self.dtype, buffer=buf, offset=offset + HEADER_BYTES
        )
        if init:
            self._ctr[:] = 0
        # Producer-side mirrors of its own counters: reading them back from shared memory
        # would create a numpy scalar per push.
        self._head = int(self._ctr[_HEAD])
        self._dropped = int(self._ctr[_DROPPED])
        self._tail_seen = int(self._ctr[_TAIL])

    # ------------------------------------------------------------------ producer side
    def push(self, rec: np.ndarray) -> bool:
        """Copy ``rec`` (a 0-d record of ``dtype``) into the ring. False (and counted in
        ``dropped``) when the ring is full. Never blocks; allocates no array."""
        head = self._head
        if head - self._tail_seen >= self.capacity:
            self._tail_seen = int(self._ctr[_TAIL])  # refresh only when it looks full
            if head - self._tail_seen >= self.capacity:
                self._dropped += 1
                self._ctr[_DROPPED] = self._dropped
                return False
        self._slots[head & self._mask] = rec
        head += 1
        self._head = head
        self._ctr[_HEAD] = head  # publish after the slot is written
        return True

    @property
    def dropped(self) -> int:
        """Records refused because the ring was full (read from shared memory)."""
        return int(self._ctr[_DROPPED])

    # ------------------------------------------------------------------ consumer side
    @property
    def head(self) -> int:
        """Records published so far."""
        return int(self._ctr[_HEAD])

    @property
    def tail(self) -> int:
        """Records consumed so far."""
        return int(self._ctr[_TAIL])

    def pending(self) -> int:
        """Records published and not yet drained."""
        return int(self._ctr[_HEAD]) - int(self._ctr[_TAIL])

    def pop_into(self, out: np.ndarray) -> bool:
        """Copy the oldest published record into ``out`` (a 0-d record of ``dtype``) and
        release its slot; False when there is none. Consumer only; allocates no array (the
        loop's side of a ring the control plane produces)."""
        tail = int(self._ctr[_TAIL])
        if int(self._ctr[_HEAD]) == tail:
            return False
        out[...] = self._slots[tail & self._mask]
        self._ctr[_TAIL] = tail + 1
        return True

    def drain(self, max_records: int | None = None) -> np.ndarray:
        """Copy out the published records not yet drained (oldest first, at most
        ``max_records``) and release their slots. Consumer only."""
        head = int(self._ctr[_HEAD])
        tail = int(self._ctr[_TAIL])
        n = head - tail
        if max_records is not None:
            n = min(n, int(max_records))
        if n <= 0:
            return np.empty(0, dtype=self.dtype)
        start = tail & self._mask
        first = min(n, self.capacity - start)
        out = np.empty(n, dtype=self.dtype)
        out[:first] = self._slots[start : start + first]
        if first < n:
            out[first:] = self._slots[: n - first]
        self._ctr[_TAIL] = tail + n  # release the slots after copying them
        return out
