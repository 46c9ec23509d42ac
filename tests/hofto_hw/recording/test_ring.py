"""The shared-memory ring: order, wrap-around, drop counting, no allocation on push."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from hofto_hw.recording.record import EVENT_DTYPE, new_record, tick_dtype
from hofto_hw.recording.ring import Ring, ring_nbytes
from hofto_hw.recording.shared import Capacities, SharedBlock


def make_ring(capacity: int, dtype=EVENT_DTYPE) -> tuple[Ring, Ring]:
    """Producer and consumer views of one ring in a plain buffer."""
    buf = memoryview(bytearray(ring_nbytes(dtype, capacity)))
    return Ring(buf, 0, dtype, capacity, init=True), Ring(buf, 0, dtype, capacity)


def push_ticks(ring: Ring, ticks: range) -> list[bool]:
    rec = new_record(ring.dtype)
    out = []
    for k in ticks:
        rec["tick"] = k
        rec["value"] = k * 0.5
        out.append(ring.push(rec))
    return out


def test_drain_returns_pushed_records_in_order():
    prod, cons = make_ring(8)
    assert push_ticks(prod, range(5)) == [True] * 5
    assert cons.pending() == 5
    got = cons.drain()
    assert got["tick"].tolist() == [0, 1, 2, 3, 4]
    assert got["value"].tolist() == [0.0, 0.5, 1.0, 1.5, 2.0]
    assert cons.drain().size == 0 and cons.pending() == 0


def test_wraps_around_and_drains_in_parts():
    prod, cons = make_ring(8)
    seen: list[int] = []
    for start in range(0, 60, 6):  # 6 at a time through 8 slots: every batch wraps sometime
        push_ticks(prod, range(start, start + 6))
        seen += cons.drain(max_records=4)["tick"].tolist()
        seen += cons.drain()["tick"].tolist()
    assert seen == list(range(60))
    assert prod.dropped == 0


def test_full_ring_drops_and_counts_without_overwriting():
    prod, cons = make_ring(4)
    assert push_ticks(prod, range(7)) == [True] * 4 + [False] * 3
    assert prod.dropped == 3 and cons.dropped == 3
    assert cons.drain()["tick"].tolist() == [0, 1, 2, 3]  # the oldest kept, nothing torn
    assert push_ticks(prod, range(10, 12)) == [True, True]  # room again after the drain
    assert cons.drain()["tick"].tolist() == [10, 11]


def test_capacity_must_be_a_power_of_two():
    with pytest.raises(ValueError, match="power of two"):
        make_ring(6)


def test_push_allocates_nothing():
    dtype = tick_dtype(6, 3)
    block = SharedBlock(dtype, Capacities(tick=1024), create=True)
    try:
        rec = new_record(dtype)
        rec["q"][:] = 1.0
        ring = block.ticks
        for _ in range(10):  # warm up (first-call caches)
            ring.push(rec)
        block.ticks.drain()
        tracemalloc.start()
        before, _ = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        for _ in range(5000):  # wraps the ring: pushes, then drops once it is full
            ring.push(rec)
        after, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        assert ring.dropped == 5000 - 1024
        assert after - before <= 256, f"push kept {after - before} bytes"
        # only small transient ints (freed at once); a record copy alone would peak ~2.8 kB
        assert peak - before <= 512, f"push peaked at {peak - before} bytes"
    finally:
        del ring
        block.close()


def test_both_sides_of_a_shared_block_see_the_same_ring():
    dtype = tick_dtype(2, 1)
    owner = SharedBlock(dtype, Capacities(tick=16), create=True)
    other = SharedBlock(dtype, Capacities(tick=16), name=owner.name)
    try:
        rec = new_record(dtype)
        rec["q"][:] = [1.0, 2.0]
        rec["tick"] = 7
        owner.ticks.push(rec)
        got = other.ticks.drain()
        assert got["tick"].tolist() == [7] and np.array_equal(got["q"][0], [1.0, 2.0])
        assert owner.ticks.pending() == 0
    finally:
        other.close()
        owner.close()
