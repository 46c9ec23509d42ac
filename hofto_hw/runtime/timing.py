"""Fixed-bin timing histograms for the loop (no allocation while recording).

1 µs bins from 0 to ``max_us``; larger values go to the last bin and ``max`` keeps the true
maximum. Percentiles are read on the slow path (summary, status, diagnostics).
"""

from __future__ import annotations

import numpy as np


class Histogram:
    """Counts of durations in µs; :meth:`add` is the hot path."""

    def __init__(self, max_us: int = 20000, counts: np.ndarray | None = None) -> None:
        #: ``counts``: a caller's int64 array of max_us + 1 bins (e.g. in the shared memory
        #: the control plane reads ``status`` from), zeroed here
        if counts is None:
            counts = np.zeros(max_us + 1, dtype=np.int64)
        elif counts.shape != (max_us + 1,) or counts.dtype != np.int64:
            raise ValueError(
                f"counts: expected int64 ({max_us + 1},), got {counts.dtype} {counts.shape}"
            )
        else:
            counts.fill(0)
        self.counts = counts
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
        return percentile_of(self.counts, p, self.max)

    def summary(self) -> dict[str, float]:
        """median, p99, p999, max [µs]."""
        return summarize(self.counts, self.max)


def percentile_of(counts: np.ndarray, p: float, max_us: float) -> float:
    """The ``p``-th percentile [µs] of histogram ``counts`` (1 µs bins, the last one open)
    whose largest value was ``max_us`` (another process's histogram: the control plane's)."""
    n = int(counts.sum())
    if n == 0:
        return 0.0
    last = len(counts) - 1
    i = int(np.searchsorted(np.cumsum(counts), p / 100.0 * n, side="left"))
    return max_us if i >= last else min(float(i + 1), max_us)


def summarize(counts: np.ndarray, max_us: float) -> dict[str, float]:
    """median, p99, p999, max [µs] of histogram ``counts``."""
    return {
        "median": round(percentile_of(counts, 50.0, max_us), 1),
        "p99": round(percentile_of(counts, 99.0, max_us), 1),
        "p999": round(percentile_of(counts, 99.9, max_us), 1),
        "max": round(max_us, 1),
    }
