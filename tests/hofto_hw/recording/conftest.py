"""Helpers of the flight-recorder tests: a child 'loop' process read line by line."""

from __future__ import annotations

import os
import queue
import subprocess
import sys
import threading
from pathlib import Path

import pytest

CHILD = Path(__file__).with_name("flight_child.py")
ROOT = Path(__file__).resolve().parents[3]

#: generous bound for states to be reached on a loaded 2-core CI machine (not a timing goal)
STATE_TIMEOUT = 120.0


class Child:
    """``flight_child.py OUT N`` in its own session (so its writer process can be killed with
    it); ``expect(prefix)`` waits for the next stdout line starting with ``prefix``."""

    def __init__(self, out: Path, n_ticks: int) -> None:
        env = dict(os.environ, PYTHONPATH=f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
        self.proc = subprocess.Popen(
            [sys.executable, str(CHILD), str(out), str(n_ticks)],
            stdout=subprocess.PIPE,
            text=True,
            env=env,
            start_new_session=True,
        )
        self.lines: queue.Queue[str] = queue.Queue()
        self.shm_name = ""
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.put(line.rstrip("\n"))
        self.lines.put("")  # EOF

    def expect(self, prefix: str) -> str:
        line = self._expect(prefix)
        if prefix == "ready":
            self.shm_name = line.split()[2]
        return line

    def _expect(self, prefix: str) -> str:
        while True:
            try:
                line = self.lines.get(timeout=STATE_TIMEOUT)
            except queue.Empty:
                raise AssertionError(f"child never printed {prefix!r}") from None
            if line.startswith(prefix):
                return line
            if line == "" and self.proc.poll() is not None:
                raise AssertionError(f"child exited ({self.proc.returncode}) before {prefix!r}")

    def kill_group(self) -> None:
        try:
            os.killpg(self.proc.pid, 9)
        except ProcessLookupError:
            pass
        self.proc.wait()


@pytest.fixture()
def child_factory():
    made: list[Child] = []

    def make(out: Path, n_ticks: int) -> Child:
        c = Child(out, n_ticks)
        made.append(c)
        return c

    yield make
    for c in made:
        if c.proc.poll() is None:
            c.kill_group()
        if c.shm_name:  # a killed group takes its resource tracker along: unlink for it
            Path("/dev/shm", c.shm_name.lstrip("/")).unlink(missing_ok=True)
