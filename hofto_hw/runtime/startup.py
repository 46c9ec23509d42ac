"""Progress lines of a slow start-up (``hofto-hw run``): silent when the loop runs in time.

The start-up compiles or loads the kernels (numba's cache: ~1 s warm, tens of seconds cold),
opens the bus, collects garbage and enables the drives. :class:`StartupProgress` is told each
phase as it begins; a helper thread prints the phase on stderr once the start-up has taken
``after`` seconds (HOFTO_HW_PROGRESS_AFTER, 1.5 by default), then every phase that begins later
and, at :meth:`done`, the total. The thread ends before the loop's first tick.
:class:`StartupSignals` makes SIGTERM and SIGINT in any of these phases a clean stop.
:class:`Helpers` starts the flight recorder's writer and the control plane first, so that they
import while the loop's process does, and awaits them once the kernels are loaded.
"""

from __future__ import annotations

import math
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, TextIO

#: the modules of the helper processes (their ``child_main``; hofto_hw.runtime.prestart)
WRITER_MODULE = "hofto_hw.recording.writer_process"
CONTROL_MODULE = "hofto_hw.control_plane.process"

#: HOFTO_HW_PROGRESS_AFTER: seconds before the first progress line (0: every phase, as
#: tools/bench_startup.py reads them); default 1.5
PROGRESS_ENV = "HOFTO_HW_PROGRESS_AFTER"


def progress_after(default: float = 1.5) -> float:
    """The seconds of :data:`PROGRESS_ENV` (``default`` when unset); UserError naming it when
    it is not a number >= 0."""
    from hofto_hw.errors import UserError

    text = os.environ.get(PROGRESS_ENV, "")
    if not text:
        return default
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value >= 0.0):
        raise UserError(f"{PROGRESS_ENV}: must be a number of seconds >= 0, got {text!r}")
    return value


class StartupProgress:
    """``phase(text)`` at each step, ``done()`` before the loop runs (see module docstring)."""

    def __init__(
        self,
        label: str = "hofto-hw run",
        after: float | None = None,
        stream: TextIO | None = None,
    ) -> None:
        self.label = label
        self.after = progress_after() if after is None else after
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

    def done(self, started: bool = True) -> float:
        """The start-up is over: stop the thread; the total is printed when lines were and it
        ``started`` (False: it failed or was stopped). Returns the start-up time [s]."""
        self._end.set()
        self._thread.join()
        took = time.monotonic() - self.t0
        if self.spoke and started:
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


class StartupInterrupted(BaseException):
    """SIGTERM or SIGINT arrived before the loop ran: what was started is unwound (drives
    disabled, bus closed, control plane and flight recorder closed). A BaseException, like
    KeyboardInterrupt: no ``except Exception`` on the way swallows it."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum
        self.name = signal.Signals(signum).name


class StartupSignals:
    """SIGTERM and SIGINT during ``hofto-hw run``'s start-up (compiling or loading the
    kernels, opening the bus, enabling): a clean stop at any phase, never the default action.

    Installed first thing; the first signal raises :class:`StartupInterrupted` where the
    start-up is, and the code around unwinds what it started. A step that starts a resource
    and only then hands it over (the flight recorder's writer, the control-plane process)
    runs inside :meth:`deferred`: a signal there raises when the step is done, so nothing is
    started that no one will close. Later signals are ignored while the first one unwinds.
    :meth:`hand_over` gives both signals to the loop's handler (a signal already received
    is passed on to it), :meth:`restore` puts back the handlers found at the start."""

    SIGNALS = (signal.SIGTERM, signal.SIGINT)

    def __init__(self) -> None:
        self.received: int | None = None
        self._raised = False
        self._defer = 0
        self._old = {s: signal.signal(s, self._handler) for s in self.SIGNALS}

    def _handler(self, signum: int, frame: object) -> None:
        if self.received is not None:
            return  # the first one is being handled
        self.received = signum
        if not self._defer:
            self._raised = True
            raise StartupInterrupted(signum)

    @contextmanager
    def deferred(self) -> Iterator[None]:
        """A step a signal must not cut in two; the signal raises when it is done."""
        self._defer += 1
        try:
            yield
        finally:
            self._defer -= 1
        if not self._defer and self.received is not None and not self._raised:
            self._raised = True
            raise StartupInterrupted(self.received)

    def hand_over(self, handler: Callable[[int, object], None]) -> None:
        """The start-up is over: ``handler`` takes both signals (and the one received, if a
        deferred step held it)."""
        for s in self.SIGNALS:
            signal.signal(s, handler)
        if self.received is not None and not self._raised:
            self._raised = True
            handler(self.received, None)

    def restore(self) -> None:
        """The handlers found at the start."""
        for s, h in self._old.items():
            signal.signal(s, h)


class Helpers:
    """The run's helper processes, started early (hofto_hw.runtime.prestart): the flight
    recorder's writer (unless ``--no-log``) and the control plane (with ``--socket`` or under
    systemd, NOTIFY_SOCKET). They set up while this process reads the config and loads the
    kernels;
    hofto_hw.commands.run's ``_start_recorder`` and ``_start_control_plane`` send them their
    arguments, and :meth:`await_ready` waits for them once the kernels are loaded, before the
    bus opens. A further helper (e.g. one started with the control plane) is one more
    attribute here, started in
    :meth:`start`, handed its arguments where its owner is built, awaited in
    :meth:`await_ready` and ended in :meth:`abandon`."""

    def __init__(self) -> None:
        self.writer: Any = None  # Prestarted of the flight recorder's writer
        self.control: Any = None  # Prestarted of the control plane
        self.recorder: Any = None  # the FlightRecorder sending the writer its arguments
        self.plane: Any = None  # the ControlPlaneProcess sending the control plane its own

    def start(self, log: bool, control: bool) -> None:
        """Start the helpers this run needs (``log``: the writer, ``control``: the control
        plane); their arguments come later. Forked from this process (hofto_hw.runtime.
        prestart): called once the loop's modules are imported, before the progress thread
        and the real-time set-up, so the children get the imports without importing."""
        from hofto_hw.runtime.prestart import Prestarted

        try:
            if log:
                self.writer = Prestarted(WRITER_MODULE, fork=True)
            if control:
                self.control = Prestarted(CONTROL_MODULE, fds=True, fork=True)
        except BaseException:
            self.abandon()
            raise

    def await_ready(self, progress: Callable[[str], None]) -> None:
        """Wait until the writer has opened its file and the control plane is up (before the
        bus opens: the loop pushes records from its first tick, the control plane sends READY,
        and a wait between opening a real bus and enabling would hold back its process data);
        UserError (one line) when the control plane did not start (a writer that did not is
        the recorder's health, reported as before)."""
        if self.recorder is not None:
            progress("waiting for the flight recorder")
            self.recorder.wait_started()
        if self.plane is not None:
            progress("waiting for the control plane")
            if not self.plane.wait_ready():
                from hofto_hw.errors import UserError

                raise UserError("the control plane process did not start (see the lines above)")

    def abandon(self) -> None:
        """End the helpers never sent their arguments (a refusal or a stop before)."""
        for child in (self.writer, self.control):
            if child is not None:
                child.abandon()
