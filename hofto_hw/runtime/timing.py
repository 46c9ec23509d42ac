"""Fixed-bin timing histograms for the loop (no allocation while recording).

1 µs bins from 0 to ``max_us``; larger values go to the last bin and ``max`` keeps the true
maximum. Percentiles are read on the slow path (summary, status, diagnostics).
"""

from __future__ import annotations

import numpy as np


class Histogram:
    """Counts of durations in µs; :meth:`add` is the hot path."""

    def __init__(self, max_us: int = 20000) -> None:
        self.counts = np.zeros(max_us + 1, dtype=np.int64)
        self.last = len(self.counts) - 1
        self.max = 0.0
        self.n = 0

    def add(self, us: float) -> None:
        i = int(us) if us > 0.0 else 0
        self.counts[i if i < self.last else self.last] += 1
        if us > self.max:
            self.max = us
        self.n += 1

    def add_many(self, us: np.ndarray) -> None:
        """:meth:`add` for a batch of durations (the flight recorder's writer; allocates)."""
        if len(us) == 0:
            return
        i = np.clip(np.asarray(us, dtype=np.float64), 0.0, float(self.last)).astype(np.int64)
        self.counts += np.bincount(i, minlength=self.last + 1)
        self.max = max(self.max, float(np.max(us)))
        self.n += len(us)

    def reset(self) -> None:
        self.counts.fill(0)
        self.max = 0.0
        self.n = 0

    def percentile(self, p: float) -> float:
        """The ``p``-th percentile [µs] (upper edge of its bin; the max for the last bin)."""
        if self.n == 0:
            return 0.0
        rank = p / 100.0 * self.n
        i = int(np.searchsorted(np.cumsum(self.counts), rank, side="left"))
        return self.max if i >= self.last else min(float(i + 1), self.max)

    def summary(self) -> dict[str, float]:
        """median, p99, p999, max [µs]."""
        return {
            "median": round(self.percentile(50.0), 1),
            "p99": round(self.percentile(99.0), 1),
            "p999": round(self.percentile(99.9), 1),
            "max": round(self.max, 1),
        }
