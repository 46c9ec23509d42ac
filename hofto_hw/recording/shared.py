"""The shared-memory segment between the loop and the writer process: a control block and
three rings (tick, event, diagnostics records of :mod:`hofto_hw.recording.record`).

Control block: u64 words, each written by one side only (``stop`` by the owner, the rest by
the writer), so neither side needs a lock.

The segment (``/dev/shm/hofto-hw-<owner pid>-<random>``) is created by the owner with its
pages reserved up front (``posix_fallocate``): a full /dev/shm is one line at creation
(free space is checked first, naming /dev/shm and the size needed), never a SIGBUS when
the loop first touches a page. The owner's pid in the name makes a segment left by a killed
run provably stale (:func:`remove_stale`: the pid is gone, or now belongs to a process
started after the segment was made).
"""

from __future__ import annotations

import os
import secrets
from dataclasses import dataclass
from multiprocessing import shared_memory
from pathlib import Path

import numpy as np

from hofto_hw.errors import UserError
from hofto_hw.recording.record import DIAG_DTYPE, EVENT_DTYPE
from hofto_hw.recording.ring import Ring, ring_nbytes

#: where POSIX shared memory lives on Linux (shm_open names are files here)
SHM_DIR = Path("/dev/shm")
#: segment names: PREFIX + "<owner pid>-<8 hex digits>"
PREFIX = "hofto-hw-"

CONTROL_BYTES = 256

#: control words (index into the u64 view); the owner writes STOP, the writer the others.
#: INDEX: rotation index of the open file; FLUSHED: records whose messages are in closed
#: chunks handed to the kernel (they survive a SIGKILL).
(STOP, PID, HEARTBEAT, BYTES, RECORDS, ERRORS, FAILING, FILES, LOST, STATE, FLUSHED,
 INDEX) = range(12)  # fmt: skip

#: writer states in the STATE word
STARTING, RUNNING, FAILED, FINISHED = 0, 1, 2, 3
STATE_NAMES = {STARTING: "starting", RUNNING: "running", FAILED: "failed", FINISHED: "finished"}


@dataclass(frozen=True)
class Capacities:
    """Slots per ring (powers of two). Ticks: 4096 = 4 s at 1 kHz of writer stall."""

    tick: int = 4096
    event: int = 256
    diag: int = 256


class SharedBlock:
    """The segment seen from one side: ``control`` (u64 words) and the rings ``ticks``,
    ``events``, ``diags``. ``create=True`` makes (and later unlinks) the segment."""

    def __init__(
        self,
        tick_dtype: np.dtype,
        caps: Capacities,
        *,
        name: str | None = None,
        create: bool = False,
    ) -> None:
        sizes = [
            ring_nbytes(tick_dtype, caps.tick),
            ring_nbytes(EVENT_DTYPE, caps.event),
            ring_nbytes(DIAG_DTYPE, caps.diag),
        ]
        total = CONTROL_BYTES + sum(sizes)
        self.segment = Segment(total, name=name, create=create)
        self.shm = self.segment.shm
        self.owner = create
        buf = self.shm.buf
        self.control = np.ndarray((CONTROL_BYTES // 8,), dtype="<u8", buffer=buf)
        off = CONTROL_BYTES
        self.ticks = Ring(buf, off, tick_dtype, caps.tick, init=create)
        off += sizes[0]
        self.events = Ring(buf, off, EVENT_DTYPE, caps.event, init=create)
        off += sizes[1]
        self.diags = Ring(buf, off, DIAG_DTYPE, caps.diag, init=create)

    @property
    def name(self) -> str:
        return self.shm.name

    def close(self) -> None:
        """Drop this side's views; the creator also unlinks the segment."""
        for attr in ("control", "ticks", "events", "diags"):
            self.__dict__.pop(attr, None)
        self.segment.close()


class Segment:
    """One shared-memory segment of ``size`` bytes, the one implementation of its life:
    ``create=True`` checks the free space, names it after this process, reserves its pages
    (``posix_fallocate``) and touches every one (the loop's first writes must not
    page-fault), and :meth:`close` unlinks it; else it attaches to ``name`` untracked.
    ``what`` names the segment in the one-line refusal, ``hint`` says what to do."""

    def __init__(
        self,
        size: int,
        *,
        name: str | None = None,
        create: bool = False,
        what: str = "the flight recorder's shared memory",
        hint: str = "free space there, or run with --no-log",
    ) -> None:
        self.shm = _create(size, what, hint) if create else _attach(name or "")
        self.owner = create
        if create:
            np.ndarray((size,), dtype=np.uint8, buffer=self.shm.buf)[:] = 0  # every page now

    @property
    def name(self) -> str:
        return self.shm.name

    @property
    def buf(self) -> memoryview:
        return self.shm.buf  # type: ignore[return-value]

    def close(self) -> None:
        """Unmap (the creator also unlinks). A view some caller still holds keeps the
        mapping until exit instead of raising."""
        try:
            self.shm.close()
        except BufferError:
            pass
        if self.owner:
            try:
                self.shm.unlink()
            except FileNotFoundError:
                pass


def _create(size: int, what: str, hint: str) -> shared_memory.SharedMemory:
    """A new segment of ``size`` bytes named after this process, its pages reserved now.

    Raises UserError (one line naming /dev/shm, ``what`` and the size) when /dev/shm has not
    the room: checked with statvfs first, then ``posix_fallocate`` (ENOSPC here, not a SIGBUS
    later when a page is first touched)."""
    need = f"{size / 1e6:.2f} MB ({size} bytes)"
    try:
        st = os.statvfs(SHM_DIR)
    except OSError as exc:
        raise UserError(f"{SHM_DIR}: cannot use POSIX shared memory: {exc.strerror}") from None
    free = st.f_bavail * st.f_frsize
    if free < size:
        raise UserError(f"{SHM_DIR}: {free / 1e6:.2f} MB free, {what} needs {need}; {hint}")
    name = f"{PREFIX}{os.getpid()}-{secrets.token_hex(4)}"
    path = SHM_DIR / name
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o600)
    except OSError as exc:
        raise UserError(f"{path}: cannot create shared memory: {exc.strerror}") from None
    try:
        os.posix_fallocate(fd, 0, size)
    except OSError as exc:
        os.close(fd)
        _unlink(path)
        raise UserError(
            f"{SHM_DIR}: cannot reserve {need} for {what}: {exc.strerror}; {hint}"
        ) from None
    os.close(fd)
    try:
        return shared_memory.SharedMemory(name=name)  # the owner's tracked handle
    except BaseException:
        _unlink(path)
        raise


def _unlink(path: Path) -> None:
    try:
        path.unlink()
    except OSError:
        pass


def remove_stale() -> list[tuple[str, int, int]]:
    """Remove the segments of runs that are gone; returns (name, bytes, owner pid) of each.

    A segment is stale when its owner's pid (in its name) is not running, or runs a process
    started after the segment was made (the pid was reused). A segment of a live owner, or
    one whose name does not say its owner, is left alone."""
    removed = []
    try:
        entries = list(SHM_DIR.glob(f"{PREFIX}*"))
    except OSError:
        return removed
    for path in entries:
        pid_text = path.name[len(PREFIX) :].split("-", 1)[0]
        if not pid_text.isdigit():
            continue
        pid = int(pid_text)
        try:
            st = path.stat()
        except OSError:
            continue
        if pid == os.getpid() or _owner_alive(pid, min(st.st_ctime, st.st_mtime)):
            continue
        try:
            path.unlink()
        except OSError:
            continue
        removed.append((path.name, st.st_size, pid))
    return removed


def _owner_alive(pid: int, made: float) -> bool:
    """Whether process ``pid`` exists and was started before ``made`` (epoch seconds) + 1 s
    (the boot time's resolution): else the pid now belongs to another process."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's live process
        pass
    started = _start_time(pid)
    return started is None or started <= made + 1.0


def _start_time(pid: int) -> float | None:
    """Start time of ``pid`` [epoch s] from /proc, or None when it cannot be read."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
        boot = next(
            float(line.split()[1])
            for line in Path("/proc/stat").read_text().splitlines()
            if line.startswith("btime ")
        )
    except (OSError, StopIteration, ValueError, IndexError):
        return None
    fields = stat[stat.rfind(")") + 2 :].split()  # after "pid (comm) "
    try:
        ticks = int(fields[19])  # field 22 of proc(5): starttime, in clock ticks since boot
    except (IndexError, ValueError):
        return None
    return boot + ticks / os.sysconf("SC_CLK_TCK")


def _attach(name: str) -> shared_memory.SharedMemory:
    """Attach to the owner's segment without letting this process's resource tracker own it
    (before Python 3.13 the tracker would unlink the owner's segment when we exit)."""
    try:
        return shared_memory.SharedMemory(name=name, track=False)  # type: ignore[call-arg]
    except TypeError:  # Python < 3.13
        from multiprocessing import resource_tracker

        shm = shared_memory.SharedMemory(name=name)
        resource_tracker.unregister(shm._name, "shared_memory")  # type: ignore[attr-defined]
        return shm
