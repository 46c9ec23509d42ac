"""What the real-time loop hands to the flight recorder: fixed-layout records and a sink.

The loop owns one preallocated record of each kind, fills it in place every tick and calls
the sink, which copies the bytes out (into a shared-memory ring read by the writer process).
Nothing here allocates on the hot path: the dtypes are built once at start-up.

Record kinds (all times in seconds on the loop's monotonic clock since start, SI values):

- tick (every tick): ``t``, ``tick``, ``q``/``qd``/``tau`` (n,) [rad, rad/s, N·m], ``q_cmd`` (n,)
  [rad] the commanded position, ``tau_ext`` (n_obs, n) [N·m] each observer's estimate in the
  order of ``observers``, ``wrench`` (6,) [N, N·m] estimated tool wrench (NaN when not
  computed), ``mode`` (u1) controller mode code, ``faults`` (u4) latched fault-class bit mask,
  ``bus_status`` (i4) the transport's exchange status, ``wakeup_us`` / ``compute_us`` (f4),
  ``monitored`` (u1) 1 when the collision monitor judged this tick (a drive powered, finite
  estimates), ``qdd_cmd`` (n,) [rad/s²] the commanded acceleration it used for its phase,
  ``sample_dt`` (f8) [s] the interval the observers integrated this tick (the bus's sample
  interval with EtherCAT DC, else the loop's dt; 0 when they held over a lost sample).
- event (rare): ``t``, ``tick``, ``kind`` (u2, a fault/event class code), ``joint`` (i2, -1 =
  none), ``category`` (i1, stop category 0/1/2, -1 = none), ``value`` (f8, e.g. the ratio or
  the offending value).
- diagnostics (10 Hz): loop and bus health counters.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Protocol

import numpy as np

DIAG_FIELDS = (
    ("t", "<f8"),
    ("ticks", "<u8"),
    ("overruns", "<u8"),
    ("wakeup_p99_us", "<f4"),
    ("compute_p99_us", "<f4"),
    ("bus_errors", "<u8"),
    ("dropped_records", "<u8"),
)


def tick_dtype(n_joints: int, n_observers: int) -> np.dtype:
    """Layout of one tick record for ``n_joints`` joints and ``n_observers`` observers.

    The same dtype OBJECT for the same sizes: numpy copies a record between arrays of one
    dtype object in ~0.2 µs, between equal but distinct dtype objects in ~50 µs (it builds
    a field-by-field cast each time), and the tick copies its record into the sink's ring."""
    return _tick_dtype(int(n_joints), max(1, int(n_observers)))


@functools.cache
def _tick_dtype(n: int, k: int) -> np.dtype:
    return np.dtype(
        [
            ("t", "<f8"),
            ("tick", "<u8"),
            ("q", "<f8", (n,)),
            ("qd", "<f8", (n,)),
            ("tau", "<f8", (n,)),
            ("q_cmd", "<f8", (n,)),
            ("tau_ext", "<f8", (k, n)),
            ("wrench", "<f8", (6,)),
            ("mode", "u1"),
            ("faults", "<u4"),
            ("bus_status", "<i4"),
            ("wakeup_us", "<f4"),
            ("compute_us", "<f4"),
            ("monitored", "u1"),
            ("qdd_cmd", "<f8", (n,)),
            ("sample_dt", "<f8"),
        ]
    )


EVENT_DTYPE = np.dtype(
    [
        ("t", "<f8"),
        ("tick", "<u8"),
        ("kind", "<u2"),
        ("joint", "<i2"),
        ("category", "i1"),
        ("value", "<f8"),
    ]
)

DIAG_DTYPE = np.dtype(list(DIAG_FIELDS))


def new_record(dtype: np.dtype) -> np.ndarray:
    """A zeroed 0-d record of ``dtype`` to fill in place (fields are views: rec["q"][:] = q)."""
    return np.zeros((), dtype=dtype)


class RecordSink(Protocol):
    """Where the loop's records go. Every method copies and returns at once: no blocking,
    no allocation; a full ring drops the record and counts it (``dropped``)."""

    dropped: int

    def push_tick(self, rec: np.ndarray) -> None: ...

    def push_event(self, rec: np.ndarray) -> None: ...

    def push_diag(self, rec: np.ndarray) -> None: ...


class NullSink:
    """A sink that keeps nothing (logging off)."""

    def __init__(self) -> None:
        self.dropped = 0

    def push_tick(self, rec: np.ndarray) -> None:
        pass

    def push_event(self, rec: np.ndarray) -> None:
        pass

    def push_diag(self, rec: np.ndarray) -> None:
        pass


class MemorySink:
    """A sink that keeps the newest ``capacity`` records of each kind in memory (tests, the
    run summary). Preallocated; overwrites the oldest when full."""

    def __init__(self, tick: np.dtype, capacity: int = 1 << 16) -> None:
        self.dropped = 0
        self.ticks = np.zeros(capacity, dtype=tick)
        self.events = np.zeros(4096, dtype=EVENT_DTYPE)
        self.diags = np.zeros(4096, dtype=DIAG_DTYPE)
        self.n_ticks = 0
        self.n_events = 0
        self.n_diags = 0

    def push_tick(self, rec: np.ndarray) -> None:
        self.ticks[self.n_ticks % self.ticks.shape[0]] = rec
        self.n_ticks += 1

    def push_event(self, rec: np.ndarray) -> None:
        self.events[self.n_events % self.events.shape[0]] = rec
        self.n_events += 1

    def push_diag(self, rec: np.ndarray) -> None:
        self.diags[self.n_diags % self.diags.shape[0]] = rec
        self.n_diags += 1

    def last_ticks(self) -> np.ndarray:
        """The kept tick records, oldest first (a copy)."""
        cap = self.ticks.shape[0]
        if self.n_ticks <= cap:
            return self.ticks[: self.n_ticks].copy()
        k = self.n_ticks % cap
        return np.concatenate([self.ticks[k:], self.ticks[:k]])

    def last_events(self) -> np.ndarray:
        """The kept events, oldest first (a copy)."""
        return self.events[: min(self.n_events, self.events.shape[0])].copy()


def observer_index(observers: Sequence[str], name: str) -> int:
    """Row of ``name`` in a tick record's ``tau_ext``; raises ValueError naming the choices."""
    try:
        return list(observers).index(name)
    except ValueError:
        raise ValueError(
            f"no observer {name!r} in the record (has: {', '.join(observers)})"
        ) from None
