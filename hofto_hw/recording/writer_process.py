"""The writer process: drains the shared-memory rings into MCAP files.

It runs at normal priority (it drops the SCHED_FIFO policy it may inherit from the loop), nice
5 once its first file is open, and never blocks the loop: the loop only touches the rings. It
finishes the file when the owner sets STOP or dies; a SIGTERM sent to the whole service
(systemd's control group) only starts a grace period, so the owner can still stop the arm while
its records are written.

A write error (disk full) abandons the current file, counts the error, discards the records
drained meanwhile (counted in LOST, so the rings never fill because of it) and retries a new
file after ``retry_seconds``.
"""

from __future__ import annotations

import os
import signal
import sys
import time

import numpy as np

from hofto_hw.recording import shared as sh
from hofto_hw.recording.flight_file import FlightFile, LogSpec, rotated_path, urdf_text
from hofto_hw.recording.frames import ArmFrames
from hofto_hw.recording.record import tick_dtype
from hofto_hw.runtime.timing import Histogram

IDLE_SLEEP = 0.005  # [s] between polls of empty rings (5 ms: 5 records at 1 kHz)
TERM_GRACE = 10.0  # [s] after a SIGTERM to this process before it finishes by itself


def _drop_realtime() -> None:
    try:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except (AttributeError, OSError):
        pass


def _step_back() -> None:
    """Nice 5 once the first file is open: behind the loop's other helpers while it drains,
    not while it starts, which the run waits for (its set-up, the /safety/thresholds track's
    imports and model, ~1 s of CPU, made its start 18.7 s at nice 5 on the shared 2-core
    machine at load 10)."""
    try:
        os.nice(5)
    except OSError:
        pass


class _Writer:
    """The drain loop's state: current file, counters in the control block."""

    def __init__(self, block: sh.SharedBlock, spec: LogSpec) -> None:
        self.block = block
        self.spec = spec
        self.ctl = block.control
        self.file: FlightFile | None = None
        self.index = 0
        self.opened_at = 0.0
        self.flushed_at = 0.0
        self.retry_at = 0.0
        self.bytes_closed = 0
        #: wall-clock ns of the loop's t = 0: the wall clock when the first records are
        #: drained minus their t (within a drain period, ~5 ms); None until then
        self.origin_ns: int | None = None
        urdf = urdf_text(spec)
        self.frames = _frames(urdf, spec) if urdf else None
        #: the loop's timing over every tick drained, for /diagnostics (systemd or not)
        self.wakeup, self.compute = Histogram(), Histogram()
        self.track = _thresholds(spec)
        self.live = None
        if spec.live_view is not None:
            from hofto_hw.recording.live import LiveView

            try:
                self.live = LiveView(spec.live_view)
            except ImportError as exc:  # the log goes on without the view
                print(f"hofto-hw flight recorder: no live view: {exc}", file=sys.stderr)

    def counters(self) -> dict[str, int]:
        c = self.ctl
        return {
            "bytes_written": int(c[sh.BYTES]),
            "records_written": int(c[sh.RECORDS]),
            "write_errors": int(c[sh.ERRORS]),
            "records_lost": int(c[sh.LOST]),
            "failing": int(c[sh.FAILING]),
        }

    def timing(self) -> dict[str, float]:
        """p99 wake-up and compute time [µs] over the ticks drained (empty before any)."""
        if self.compute.n == 0:
            return {}
        return {
            "wakeup_p99_us": self.wakeup.percentile(99.0),
            "compute_p99_us": self.compute.percentile(99.0),
        }

    def _open(self, now: float) -> None:
        """Open the next free file name (existing files are never overwritten)."""
        while True:
            path = rotated_path(self.spec.path, self.index)
            self.index += 1
            try:
                self.file = FlightFile(
                    self.spec,
                    path,
                    self.index - 1,
                    frames=self.frames,
                    live=self.live,
                    thresholds=self.track,
                )
                break
            except FileExistsError:
                continue
        self.ctl[sh.FILES] += 1
        self.ctl[sh.INDEX] = self.index - 1
        self.opened_at = self.flushed_at = now

    def _fail(self, now: float) -> None:
        self.ctl[sh.ERRORS] += 1
        self.ctl[sh.FAILING] = 1
        self.ctl[sh.STATE] = sh.FAILED
        if self.file is not None:
            self.bytes_closed += self.file.bytes
            self.file.abandon()
        self.file = None
        self.retry_at = now + self.spec.retry_seconds

    def _sync_bytes(self) -> None:
        self.ctl[sh.BYTES] = self.bytes_closed + (self.file.bytes if self.file else 0)

    def step(self, now: float) -> int:
        """Drain once; returns the records drained."""
        b = self.block
        ticks, events, diags = b.ticks.drain(), b.events.drain(), b.diags.drain()
        n = len(ticks) + len(events) + len(diags)
        if self.origin_ns is None and n:
            t0 = min(float(r["t"][0]) for r in (ticks, events, diags) if len(r))
            self.origin_ns = time.time_ns() - round(t0 * 1e9)
        if len(ticks):
            self.wakeup.add_many(ticks["wakeup_us"])
            self.compute.add_many(ticks["compute_us"])
        if self.live is not None:
            self.live.poll()
        if self.file is None and now >= self.retry_at:
            try:
                self._open(now)
                self.ctl[sh.FAILING] = 0
                self.ctl[sh.STATE] = sh.RUNNING
            except OSError:
                self._fail(now)
        if self.file is None:
            self.ctl[sh.LOST] += n
            return n
        counted = False
        if not self.file.messages:
            self.file.origin_ns = self.origin_ns or 0
        if self.track is not None and len(events):  # a profile switch: before its ticks
            self.track.note_events(events)
        try:
            if len(ticks):
                self.file.write_ticks(ticks)
            if len(events):
                self.file.write_events(events)
            if len(diags):
                self.file.write_diags(diags, self.counters(), self.timing())
            self.ctl[sh.RECORDS] += n
            counted = True
            if now - self.flushed_at >= self.spec.flush_seconds:
                self.file.flush()
                self.flushed_at = now
                self.ctl[sh.FLUSHED] = self.ctl[sh.RECORDS]
        except OSError:
            # what is not in a closed chunk goes with the abandoned file: the records counted
            # since the last flush and this batch (counted once, whichever step failed)
            unflushed = int(self.ctl[sh.RECORDS] - self.ctl[sh.FLUSHED])
            self.ctl[sh.RECORDS] = self.ctl[sh.FLUSHED]
            self.ctl[sh.LOST] += unflushed + (0 if counted else n)
            self._fail(now)
        if self.file is not None:
            try:
                self._maybe_rotate(now)
            except OSError:  # the records are in the finished file; the new one failed
                self._fail(now)
        self._sync_bytes()
        return n

    def _maybe_rotate(self, now: float) -> None:
        f, spec = self.file, self.spec
        assert f is not None
        by_size = spec.rotate_bytes and f.bytes >= spec.rotate_bytes
        by_time = spec.rotate_seconds and now - self.opened_at >= spec.rotate_seconds
        if by_size or by_time:
            f.finish()
            self.ctl[sh.FLUSHED] = self.ctl[sh.RECORDS]
            self.bytes_closed += f.bytes
            self._open(now)

    def finish(self) -> None:
        if self.file is None:
            return
        try:
            self.file.finish()
            self.ctl[sh.FLUSHED] = self.ctl[sh.RECORDS]
        except OSError:
            self._fail(time.monotonic())
            return
        self._sync_bytes()
        self.file = None


def _frames(urdf: str, spec: LogSpec) -> ArmFrames | None:
    """The arm's frames for /tf; None (a log without /tf, said on stderr) if the URDF does
    not give them: the log itself must not depend on it."""
    try:
        return ArmFrames(urdf, spec.joint_names, spec.tool_frame)
    except (ValueError, RuntimeError) as exc:
        print(f"hofto-hw flight recorder: no /tf in the log: {exc}", file=sys.stderr)
        return None


def _thresholds(spec: LogSpec) -> object | None:
    """The monitor's thresholds re-computed from the records (/safety/thresholds) when the
    log carries the run's config; None otherwise (said on stderr when it should have)."""
    from hofto_hw.recording.attachments import CONFIG

    attached = {name: data for name, _media, data in spec.attachments}
    if CONFIG not in attached or not spec.observers:
        return None
    try:
        from hofto_hw.replay.levels_track import ThresholdTrack

        track = ThresholdTrack(attached, spec.metadata, spec.joint_names, spec.observers)
        if track.mon.backend != "numba":  # numpy: ~250 µs per tick, a quarter of a 1 kHz tick
            print(
                "hofto-hw flight recorder: no /safety/thresholds (the run's monitor is not on "
                "the compiled kernels; `hofto-hw log plot` draws them from the log)",
                file=sys.stderr,
            )
            return None
        return track
    except LookupError:  # a thresholds-file monitor (older runs, tests): nothing to track
        return None
    except Exception as exc:  # the log must not depend on it
        print(f"hofto-hw flight recorder: no /safety/thresholds: {exc}", file=sys.stderr)
        return None


def writer_main(
    shm_name: str,
    n_joints: int,
    n_observers: int,
    caps: sh.Capacities,
    spec: LogSpec,
    cpus: list[int] | None = None,
    term: list[float] | None = None,
) -> None:
    """The writer process's work, once it has its arguments. ``term[0]``: the monotonic time
    of a SIGTERM to this process (0: none yet), kept by its handler."""
    _drop_realtime()
    if cpus:
        try:
            os.sched_setaffinity(0, cpus)
        except OSError:  # CPUs outside our cpuset: keep the inherited affinity
            pass
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the owner decides when to stop
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # RLIMIT_FSIZE: get EFBIG, not death
    if term is None:
        term = [0.0]
        signal.signal(signal.SIGTERM, lambda *_: term.__setitem__(0, time.monotonic()))
    parent = os.getppid()
    block = sh.SharedBlock(tick_dtype(n_joints, n_observers), caps, name=shm_name)
    ctl = block.control
    ctl[sh.PID] = os.getpid()
    w = _Writer(block, spec)
    try:
        _run(w, ctl, parent, term)
    except BaseException:
        # A bug, not a full disk: count it, leave the file for `log recover`, and die (the
        # owner sees writer_alive False). The traceback goes to stderr (the journal).
        ctl[sh.ERRORS] += 1
        ctl[sh.STATE] = sh.FAILED
        if w.file is not None:
            w.file.abandon()
        raise
    if ctl[sh.STATE] != sh.FAILED:
        ctl[sh.STATE] = sh.FINISHED
    if w.live is not None:
        w.live.close()
    del ctl, w
    block.close()


def _run(w: _Writer, ctl: np.ndarray, parent: int, term: list[float]) -> None:
    """Drain until stopped (STOP word, owner gone, or SIGTERM grace over), then finish."""
    stepped_back = False
    while True:
        now = time.monotonic()
        stop = bool(ctl[sh.STOP]) or os.getppid() != parent
        stop = stop or (term[0] > 0.0 and now - term[0] > TERM_GRACE)
        n = w.step(now)
        ctl[sh.HEARTBEAT] += 1
        if not stepped_back:
            _step_back()
            stepped_back = True
        if stop:
            while w.step(time.monotonic()):  # whatever the owner pushed before stopping
                pass
            break
        if n == 0:
            time.sleep(IDLE_SLEEP)
    w.finish()


def preload() -> None:
    """What the writer imports beyond this module, before its arguments arrive (it starts
    while the loop's process imports): the /safety/thresholds track's modules."""
    from importlib import import_module

    for name in (
        "hofto_hw.recording.attachments",
        "hofto_hw.replay.levels_track",
        "hofto_hw.replay.reproduce",
    ):
        import_module(name)


def child_main(args: tuple, fds: list[int], term: list[float]) -> int:
    """Entry point of the writer process (``python -m hofto_hw.runtime.prestart`` with this
    module, as FlightRecorder starts it): ``args`` = (shm name, n_joints, n_observers, caps,
    spec, cpus)."""
    shm_name, *rest = args
    writer_main(shm_name, *rest, term=term)
    return 0
