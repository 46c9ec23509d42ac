"""FlightRecorder: the loop's RecordSink backed by shared-memory rings and a writer process.

The loop calls ``push_tick`` / ``push_event`` / ``push_diag`` (a copy into a ring slot, no
lock, no allocation, never blocks); the writer process it owns turns the records into MCAP
(:mod:`hofto_hw.recording.writer_process`). :meth:`health` says whether the writer is alive,
what it wrote and what was lost; a dead writer or a full disk is reported, never raised into
the loop — whether that is a fault is the caller's policy.

    rec = FlightRecorder(LogSpec(path, joint_names, observers, attachments=...))
    rec.start()
    ... rec.push_tick(tick_record) every tick ...
    rec.close()          # finishes the file (also on SIGTERM of the owner, if it calls close)
"""

from __future__ import annotations

import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hofto_hw.errors import UserError
from hofto_hw.recording import shared as sh
from hofto_hw.recording.log_spec import LogSpec, rotated_path
from hofto_hw.recording.record import tick_dtype
from hofto_hw.runtime.prestart import Prestarted
from hofto_hw.runtime.realtime import cpus_beside_loop
from hofto_hw.runtime.startup import WRITER_MODULE


@dataclass
class RecorderHealth:
    """A snapshot of the recorder: ``writer_alive``, ``state`` (starting/running/failed/
    finished), ``bytes_written`` (all files), ``records_written``, ``records_flushed`` (in
    closed chunks: they survive a SIGKILL), ``dropped`` (refused by a
    full ring, all kinds), ``records_lost`` (drained while the disk failed), ``write_errors``,
    ``disk_failing`` (the last write failed and no file is open), ``files`` opened, the
    ``current_file``, ``pending`` ticks in the ring."""

    writer_alive: bool
    state: str
    bytes_written: int
    records_written: int
    records_flushed: int
    dropped: int
    records_lost: int
    write_errors: int
    disk_failing: bool
    files: int
    current_file: Path | None
    pending: int

    @property
    def ok(self) -> bool:
        """Writer alive, no write failing now."""
        return self.writer_alive and not self.disk_failing


class FlightRecorder:
    """A RecordSink (see record.py) writing MCAP through a writer process.

    ``n_joints`` comes from the spec's joint names, the tick layout from ``tick_dtype(n,
    len(spec.observers))``. ``cpus``: CPUs for the writer; by default the CPUs outside the
    caller's affinity if it is pinned (a writer sharing the loop's CPU costs wake-up latency:
    p99 34 µs pinned apart vs up to 300 µs sharing, tools/bench_recorder.py). ``writer``: its
    process started already (a :class:`~hofto_hw.runtime.prestart.Prestarted` of
    ``runtime.startup.WRITER_MODULE``, importing while the caller starts up); :meth:`start`
    sends it its arguments.
    """

    def __init__(
        self,
        spec: LogSpec,
        caps: sh.Capacities | None = None,
        *,
        cpus: list[int] | None = None,
        writer: Prestarted | None = None,
    ) -> None:
        self.spec = spec
        self.caps = caps or sh.Capacities()
        self.n_joints = len(spec.joint_names)
        self.n_observers = len(spec.observers)
        self.tick_dtype = tick_dtype(self.n_joints, self.n_observers)
        self._cpus = cpus
        self._block: sh.SharedBlock | None = None
        self._proc: Prestarted | None = writer
        self._final: RecorderHealth | None = None
        #: (name, bytes, owner pid) of the stale segments :meth:`start` removed
        self.removed_stale: list[tuple[str, int, int]] = []

    # ---------------------------------------------------------------- lifecycle
    def start(self, timeout: float = 60.0, *, wait: bool = True) -> FlightRecorder:
        """Remove stale segments of dead runs (:attr:`removed_stale`), create the rings
        (UserError when /dev/shm has not the room), start the writer process (or hand the
        one given as ``writer`` its arguments) and, with ``wait``, wait until it has opened
        the first file (or failed, or died), at most ``timeout`` [s] (:meth:`wait_started`).
        Returns self; check :meth:`health` for failures."""
        if self._block is not None:
            raise RuntimeError("flight recorder already started")
        if Path(self.spec.path).exists():
            raise UserError(f"{self.spec.path}: exists; a flight log is never overwritten")
        Path(self.spec.path).parent.mkdir(parents=True, exist_ok=True)
        self.removed_stale = sh.remove_stale()  # segments of killed runs: room for ours
        self._block = sh.SharedBlock(self.tick_dtype, self.caps, create=True)
        b = self._block
        # the rings' own push as instance attributes (they shadow the methods below): the
        # loop's sink.push_tick(rec) is then one Python frame, the ring's
        self.push_tick, self.push_event, self.push_diag = (  # type: ignore[method-assign]
            b.ticks.push,
            b.events.push,
            b.diags.push,
        )
        # A fresh interpreter (not multiprocessing): it does not depend on how the loop's
        # __main__ was started, inherits no threads or locks, and owns no resource tracker
        # of ours. It notices our death by its parent pid changing.
        try:
            if self._proc is None:
                self._proc = Prestarted(WRITER_MODULE)
        except BaseException:  # no writer: the segment must not outlive us in /dev/shm
            b.close()
            self._block = None
            raise
        cpus = self._cpus if self._cpus is not None else cpus_beside_loop()
        self._proc.send((b.name, self.n_joints, self.n_observers, self.caps, self.spec, cpus))
        if wait:
            self.wait_started(timeout)
        return self

    def wait_started(self, timeout: float = 60.0) -> bool:
        """Wait until the writer has opened the first file (or failed, or died), at most
        ``timeout`` [s]; whether it left the starting state."""
        b, proc = self._block, self._proc
        if b is None or proc is None:
            raise RuntimeError("flight recorder not started")
        deadline = time.monotonic() + timeout
        while int(b.control[sh.STATE]) == sh.STARTING and proc.poll() is None:
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.01)
        return int(b.control[sh.STATE]) != sh.STARTING

    def close(self, timeout: float = 10.0) -> RecorderHealth:
        """Ask the writer to drain and finish the file, wait up to ``timeout`` [s] (then
        kill it; a writer still starting is given its start first, :meth:`wait_started`),
        free the shared memory. Returns the final health. Idempotent."""
        if self._final is not None:
            return self._final
        if self._block is None:
            raise RuntimeError("flight recorder not started")
        self._block.control[sh.STOP] = 1
        assert self._proc is not None
        self.wait_started()  # a writer still importing opens its file, then sees STOP
        try:
            self._proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait()
        self._final = self.health()
        self.push_tick = self.push_event = self.push_diag = _discard  # type: ignore[method-assign]
        self._block.close()
        return self._final

    def __enter__(self) -> FlightRecorder:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ---------------------------------------------------------------- RecordSink
    # :meth:`start` replaces these three by the rings' own ``push`` (``Ring.push``: the copy
    # into a slot, then the publish; False and counted when full), :meth:`close` by a discard
    def push_tick(self, rec: np.ndarray) -> None:
        """Copy one tick record (0-d, ``self.tick_dtype``) into the ring."""
        raise RuntimeError("flight recorder not started")

    def push_event(self, rec: np.ndarray) -> None:
        """Copy one event record (0-d, EVENT_DTYPE) into the ring."""
        raise RuntimeError("flight recorder not started")

    def push_diag(self, rec: np.ndarray) -> None:
        """Copy one diagnostics record (0-d, DIAG_DTYPE) into the ring."""
        raise RuntimeError("flight recorder not started")

    @property
    def dropped(self) -> int:
        """Records refused by full rings (all kinds) since start."""
        if self._final is not None:
            return self._final.dropped
        b = self._block
        if b is None:
            return 0
        return b.ticks.dropped + b.events.dropped + b.diags.dropped

    # ---------------------------------------------------------------- health
    def health(self) -> RecorderHealth:
        """Counters from the shared control block (cheap; not for every tick)."""
        if self._final is not None:
            return self._final
        b = self._block
        if b is None or self._proc is None:
            raise RuntimeError("flight recorder not started")
        c = b.control
        files = int(c[sh.FILES])
        return RecorderHealth(
            writer_alive=self._proc.poll() is None,
            state=sh.STATE_NAMES.get(int(c[sh.STATE]), "unknown"),
            bytes_written=int(c[sh.BYTES]),
            records_written=int(c[sh.RECORDS]),
            records_flushed=int(c[sh.FLUSHED]),
            dropped=self.dropped,
            records_lost=int(c[sh.LOST]),
            write_errors=int(c[sh.ERRORS]),
            disk_failing=bool(c[sh.FAILING]),
            files=files,
            current_file=rotated_path(Path(self.spec.path), int(c[sh.INDEX])) if files else None,
            pending=b.ticks.pending(),
        )

    @property
    def shm_name(self) -> str | None:
        """Name of the shared-memory segment (/dev/shm/<name> on Linux) while running."""
        return self._block.name if self._block is not None and self._final is None else None

    @property
    def writer_pid(self) -> int | None:
        return self._proc.pid if self._proc is not None else None


def _discard(rec: np.ndarray) -> bool:
    return False
