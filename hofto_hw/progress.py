"""Progress lines on stderr for long work (reading a big recording, a long replay).

Silent for short work: the first line comes after ``after`` seconds, then one every
``every`` seconds. Lines go to stderr only, so ``--json`` on stdout is never mixed with them,
and they are plain lines (no carriage returns), readable in a log file too.
"""

from __future__ import annotations

import sys
import time
from typing import TextIO


class Progress:
    """``update(done)`` prints ``<label>: <done>/<total> (<pct> %)`` at most every ``every`` s."""

    def __init__(
        self,
        label: str,
        total: int,
        *,
        after: float = 2.0,
        every: float = 3.0,
        stream: TextIO | None = None,
    ) -> None:
        self.label = label
        self.total = max(int(total), 1)
        self.every = every
        self.stream = stream if stream is not None else sys.stderr
        self._next = time.monotonic() + after

    def update(self, done: int) -> None:
        now = time.monotonic()
        if now < self._next:
            return
        self._next = now + self.every
        pct = 100.0 * done / self.total
        print(f"{self.label}: {done}/{self.total} ({pct:.0f} %)", file=self.stream, flush=True)
