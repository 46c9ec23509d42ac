"""Progress lines of a slow start-up (``hofto-hw run``): silent when the loop runs in time.

The start-up compiles or loads the kernels (numba's cache: ~1 s warm, tens of seconds cold),
opens the bus, collects garbage and enables the drives. :class:`StartupProgress` is told each
phase as it begins; a helper thread prints the phase on stderr once the start-up has taken
``after`` seconds, then every phase that begins later and, at :meth:`done`, the total. The
thread ends before the loop's first tick.
"""

from __future__ import annotations

import sys
import threading
import time
from typing import TextIO


class StartupProgress:
    """``phase(text)`` at each step, ``done()`` before the loop runs (see module docstring)."""

    def __init__(
        self, label: str = "hofto-hw run", after: float = 1.5, stream: TextIO | None = None
    ) -> None:
        self.label = label
        self.after = after
        self.stream = stream if stream is not None else sys.stderr
        self.t0 = time.monotonic()
        self.spoke = False  # a line was printed
        self._late = False  # the start-up took longer than ``after``
        self._phase = ""
        self._said = ""
        self._lock = threading.Lock()
        self._end = threading.Event()
        self._thread = threading.Thread(target=self._watch, name="startup-progress", daemon=True)
        self._thread.start()

    def phase(self, text: str) -> None:
        """The start-up now does ``text`` (e.g. "enabling the drives")."""
        with self._lock:
            self._phase = text
            if self._late:
                self._say()

    def done(self) -> float:
        """The start-up is over: stop the thread; the total is printed when lines were. Returns
        the start-up time [s]."""
        self._end.set()
        self._thread.join()
        took = time.monotonic() - self.t0
        if self.spoke:
            self._print(f"started in {took:.1f} s")
        return took

    def _watch(self) -> None:
        if self._end.wait(self.after):
            return
        with self._lock:
            self._late = True
            self._say()

    def _say(self) -> None:
        if self._phase and self._phase != self._said:
            self._said = self._phase
            self.spoke = True
            self._print(f"starting: {self._phase} ({time.monotonic() - self.t0:.1f} s)")

    def _print(self, text: str) -> None:
        print(f"{self.label}: {text}", file=self.stream, flush=True)
