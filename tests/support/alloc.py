"""The runtime tests' allocation measurement of the tick."""

from __future__ import annotations

import gc
import tracemalloc
from typing import Any


def _traced() -> int:
    """Bytes traced now, after a full collection. The collection also empties the free lists
    of the built-in types (gc.collect's documented behaviour): a float or tuple parked on a
    free list stays traced, so without it the figure moves by what those lists happen to
    hold at the two readings (seen up to ~7 kB on the drag tick's Python path)."""
    gc.collect()
    return tracemalloc.get_traced_memory()[0]


def tick_memory(system: Any, ticks: int = 3000) -> tuple[int, int]:
    """Run ``system`` (warmed up by the caller) under tracemalloc: 10 more warm-up ticks,
    then two windows of ``ticks`` ticks. Returns (bytes kept, peak above the start) [B].

    Bytes kept is the smaller of the two windows' growth: a tick that keeps something grows
    both by the same amount (3000 ticks x 8 B is 24 kB), while a bounded cache filled once
    (numpy's, the interpreter's) grows only one of them. The peak is the first window's,
    above a start whose free lists the 10 ticks refilled (their refill is no temporary)."""
    tracemalloc.start()
    try:
        start = _traced()
        system.loop.run(max_ticks=10)
        warm = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        system.loop.run(max_ticks=ticks)
        peak = tracemalloc.get_traced_memory()[1]
        middle = _traced()
        system.loop.run(max_ticks=ticks)
        end = _traced()
    finally:
        tracemalloc.stop()
    return min(middle - start, end - middle), peak - warm
