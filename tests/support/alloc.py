"""The runtime tests' allocation measurement of the tick."""

from __future__ import annotations

import tracemalloc
from typing import Any


def tick_memory(system: Any, ticks: int = 3000) -> tuple[int, int]:
    """Run ``ticks`` ticks of ``system`` (warmed up by the caller) under tracemalloc after
    10 more warm-up ticks; returns (bytes kept, peak above the start) [B]."""
    tracemalloc.start()
    system.loop.run(max_ticks=10)
    before, _ = tracemalloc.get_traced_memory()
    system.loop.run(max_ticks=ticks)
    after, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return after - before, peak - before
