"""The fixed-rate loop: clock, deadlines, overrun accounting, timing histograms.

``RealClock`` sleeps to absolute CLOCK_MONOTONIC deadlines (clock_nanosleep TIMER_ABSTIME);
a wake-up later than a whole period counts the skipped deadlines as missed (overruns) and the
next deadline stays on the original grid. ``SimClock`` runs the ticks back to back (``--clock
sim``): loop time advances one period per tick and :meth:`SimClock.stall` injects missed
deadlines for tests. The tick gets the real dt (periods since the last tick).
"""

from __future__ import annotations

import time
from collections.abc import Callable

from hofto_hw.runtime.realtime import quiet_gc, sleep_until
from hofto_hw.runtime.tick import Tick
from hofto_hw.runtime.timing import Histogram


class RealClock:
    """Absolute-deadline sleeping at ``period_ns``."""

    sim = False

    def __init__(self, period_ns: int) -> None:
        self.period_ns = int(period_ns)
        self.start_ns = 0
        self.deadline = 0

    def start(self) -> None:
        self.start_ns = time.monotonic_ns()
        self.deadline = self.start_ns + self.period_ns

    def wait(self) -> tuple[int, int]:
        """Sleep to the next deadline; returns (lateness [ns] after it, whole periods of that
        lateness = deadlines missed; the next deadline is the first one still ahead)."""
        sleep_until(self.deadline)
        now = time.monotonic_ns()
        late = now - self.deadline
        missed = late // self.period_ns if late >= self.period_ns else 0
        self.deadline += (missed + 1) * self.period_ns
        return late, missed

    def elapsed(self) -> float:
        """Loop time [s] of the deadline just served."""
        return (self.deadline - self.period_ns - self.start_ns) * 1e-9


class SimClock:
    """Back-to-back ticks; loop time advances one period per tick (plus injected stalls)."""

    sim = True

    def __init__(self, period_ns: int) -> None:
        self.period_ns = int(period_ns)
        self.ticks = 0
        self._stall = 0

    def start(self) -> None:
        self.ticks = 0

    def stall(self, periods: int) -> None:
        """Make the next wait report ``periods`` missed deadlines (a host that stole the CPU)."""
        self._stall += int(periods)

    def wait(self) -> tuple[int, int]:
        missed, self._stall = self._stall, 0
        self.ticks += missed + 1
        return 0, missed

    def elapsed(self) -> float:
        return self.ticks * self.period_ns * 1e-9


class Loop:
    """Runs ``tick`` on ``clock`` until ``should_stop()`` or ``max_ticks``.

    ``wakeup`` / ``compute``: :class:`Histogram` [µs] of the wake-up latency (time after the
    deadline) and of the tick's own run time.
    """

    def __init__(self, tick: Tick, clock: RealClock | SimClock) -> None:
        self.tick = tick
        self.clock = clock
        self.period = clock.period_ns * 1e-9
        self.wakeup = Histogram()
        self.compute = Histogram()
        self.ticks = 0
        self.t = 0.0
        self.alive_ns = 0  # monotonic time of the last finished tick (for the watchdog)
        self.running = False
        self.started = False
        #: when set, the dt the tick gets whatever the clock did: a simulated bus advances its
        #: plant one cycle per exchange, so after a stall its data is still one cycle apart
        self.data_dt: float | None = None
        #: the first ticks of a real-time run warm caches and fault in pages (measured here:
        #: up to ~20 ms once): their missed deadlines are counted but start no streak
        self.grace_ticks = 0 if clock.sim else round(0.1e9 / clock.period_ns)
        #: the control channel's loop side (hofto_hw.control_plane.port.LoopPort): polled
        #: after every tick, before the next wait (never waits itself)
        self.port = None

    def run(self, max_ticks: int | None = None, should_stop: Callable[[], bool] | None = None):
        """Run up to ``max_ticks`` more ticks (gc frozen and off inside); returns the total."""
        tick, clock = self.tick, self.clock
        limit = -1 if max_ticks is None else self.ticks + int(max_ticks)
        compute_us = 0.0
        perf = time.perf_counter_ns
        mono = time.monotonic_ns
        self.running = True
        with quiet_gc():
            if not self.started:
                clock.start()  # once: later calls continue on the same deadline grid
                self.started = True
            while self.ticks != limit:
                late_ns, missed = clock.wait()
                t0 = perf()
                wake_us = late_ns * 1e-3
                dt = (missed + 1) * self.period if self.data_dt is None else self.data_dt
                if self.ticks < self.grace_ticks and missed:
                    tick.overruns += missed  # counted, but not held against the streak
                    missed = 0
                self.t += dt  # loop time as the data sees it (see data_dt)
                tick.step(self.t, dt, wake_us, missed, compute_us)
                compute_us = (perf() - t0) * 1e-3
                if not clock.sim:
                    self.wakeup.add(wake_us)
                self.compute.add(compute_us)
                self.ticks += 1
                self.alive_ns = mono()
                if self.port is not None:
                    self.port.poll()
                if should_stop is not None and should_stop():
                    break
        self.running = False
        return self.ticks
