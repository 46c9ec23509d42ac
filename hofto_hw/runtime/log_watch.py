"""Flight-recorder health as a safety input: a slow thread reads the recorder's shared
counters every ``interval`` seconds and raises the tick's ``log_failure`` request, which the
tick reports as Fault.LOG_FAILURE to the StopController (whose category comes from
``safety.categories.log_failure``; null = report only, the default). The log never stops the
loop by itself: only that configured category does.

Failing means: the writer process is dead, the disk is failing (a write raised), or records
were dropped (ring full) or lost (drained while the disk failed) since the last check. A
failure that stops (e.g. the disk recovers) clears the request, so a reset can succeed.
"""

from __future__ import annotations

import threading
from typing import Any


class LogWatch:
    """Polls ``recorder.health()`` (hofto_hw.recording.recorder.FlightRecorder) for ``tick``
    (hofto_hw.runtime.tick.Tick: attributes ``log_failure`` bool and ``log_failure_value``,
    the records dropped + lost so far). :meth:`check` is one poll (tests call it directly)."""

    def __init__(self, recorder: Any, tick: Any, interval: float = 0.1) -> None:
        self.recorder = recorder
        self.tick = tick
        self.interval = float(interval)
        self.checks = 0
        self.reason = ""  # why the last failing check failed (slow path, for people)
        self._seen = 0
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, name="hofto-logwatch", daemon=True)

    def check(self) -> bool:
        """One poll: sets the tick's request; returns True when the log is failing."""
        h = self.recorder.health()
        lost = int(h.dropped) + int(h.records_lost)
        reasons = []
        if not h.writer_alive:
            reasons.append("writer process dead")
        if h.disk_failing:
            reasons.append("disk failing")
        if lost > self._seen:
            reasons.append(f"{lost - self._seen} records dropped/lost")
        self._seen = lost
        self.checks += 1
        failing = bool(reasons)
        if failing:
            self.reason = ", ".join(reasons)
        self.tick.log_failure_value = float(lost)
        self.tick.log_failure = failing
        return failing

    def start(self) -> LogWatch:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._done.set()
        self._thread.join(timeout=2.0)

    def _run(self) -> None:
        while not self._done.wait(self.interval):
            try:
                self.check()
            except RuntimeError:  # the recorder was closed under us: the run is ending
                return
