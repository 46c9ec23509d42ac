"""Real-time setup of the loop thread and absolute-deadline sleeping.

- :func:`sleep_until` sleeps to an absolute CLOCK_MONOTONIC deadline with libc's
  clock_nanosleep(TIMER_ABSTIME) through ctypes (Python has no time.clock_nanosleep), so a
  late wake-up does not shift later deadlines.
- :func:`setup` applies ``loop.realtime``: SCHED_FIFO at ``loop.priority`` for the calling
  thread, mlockall(MCL_CURRENT | MCL_FUTURE), CPU affinity, and the CPU wake-up latency
  limit ``loop.cpu_latency_us`` (a PM QoS request held open on /dev/cpu_dma_latency, as
  cyclictest does: idle CPUs stay out of sleep states that take longer to leave, and the
  kernel drops the request when the process ends, however it ends). ``required`` raises
  ConfigError naming the missing capability; ``preferred`` warns once and goes on; ``off``
  tries nothing. :func:`drop_realtime` gives all of it back.
- :func:`quiet_gc` freezes the objects built at start-up and disables the collector for the
  loop (no collection pause inside a tick).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import os
import struct
import sys
import time
from dataclasses import dataclass, field

from hofto_hw.errors import ConfigError

CLOCK_MONOTONIC = 1
TIMER_ABSTIME = 1
MCL_CURRENT, MCL_FUTURE = 1, 2
EINTR = 4

#: the kernel's global PM QoS CPU latency request (a 4-byte int in µs; held while open)
CPU_LATENCY_DEVICE = "/dev/cpu_dma_latency"
_latency_fd: int | None = None

_libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)


class _Timespec(ctypes.Structure):
    _fields_ = [("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long)]


_clock_nanosleep = _libc.clock_nanosleep
_clock_nanosleep.argtypes = [
    ctypes.c_int,
    ctypes.c_int,
    ctypes.POINTER(_Timespec),
    ctypes.POINTER(_Timespec),
]
_clock_nanosleep.restype = ctypes.c_int
_deadline = _Timespec()
_deadline_ref = ctypes.byref(_deadline)


def sleep_until(deadline_ns: int) -> None:
    """Sleep until CLOCK_MONOTONIC reaches ``deadline_ns`` (time.monotonic_ns() scale); at
    once, without a system call, when it has passed (a late tick catching up: on the KVM
    guest we measure on, clock_nanosleep with a passed deadline still takes ~31 µs)."""
    if time.monotonic_ns() >= deadline_ns:
        return
    _deadline.tv_sec = deadline_ns // 1_000_000_000
    _deadline.tv_nsec = deadline_ns % 1_000_000_000
    while _clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, _deadline_ref, None) == EINTR:
        pass  # a signal handler ran; the deadline is absolute, so simply sleep again


@dataclass
class RealtimeReport:
    """What :func:`setup` achieved; ``missing`` names what could not be had."""

    fifo: bool = False
    locked: bool = False
    cpus: list[int] | None = None
    cpu_latency_us: int | None = None  # the wake-up latency limit held [µs]; None = none
    missing: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)  # said in describe(), not missing

    def describe(self) -> str:
        parts = [
            "SCHED_FIFO" if self.fifo else "SCHED_OTHER",
            "memory locked" if self.locked else "memory not locked",
        ]
        if self.cpus is not None:
            parts.append(f"CPUs {self.cpus}")
        if self.cpu_latency_us is not None:
            parts.append(f"CPU wake-up latency <= {self.cpu_latency_us} µs")
        return ", ".join(parts + self.notes)


def _try_fifo(priority: int) -> str | None:
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except PermissionError:
        return f"CAP_SYS_NICE (or RLIMIT_RTPRIO >= {priority}) for SCHED_FIFO priority {priority}"
    except OSError as exc:
        return f"SCHED_FIFO priority {priority}: {exc.strerror}"
    return None


def _try_mlockall() -> str | None:
    if _libc.mlockall(MCL_CURRENT | MCL_FUTURE) != 0:
        err = ctypes.get_errno()
        if err in (1, 12):  # EPERM, ENOMEM (RLIMIT_MEMLOCK too small)
            return "CAP_IPC_LOCK (or RLIMIT_MEMLOCK unlimited) for mlockall"
        return f"mlockall: {os.strerror(err)}"
    return None


def hold_cpu_latency(us: int) -> str | None:
    """Hold a PM QoS request that no CPU takes longer than ``us`` [µs] to wake up, until
    :func:`release_cpu_latency` or the process ends; returns what is missing, or None."""
    global _latency_fd
    release_cpu_latency()
    what = f"a CPU wake-up latency limit of {us} µs"
    try:
        fd = os.open(CPU_LATENCY_DEVICE, os.O_WRONLY)  # not inherited by children (PEP 446)
    except PermissionError:
        return (
            f"write access to {CPU_LATENCY_DEVICE} (root, or configs/udev/"
            f"60-hofto-hw-cpu-latency.rules) for {what}"
        )
    except OSError as exc:
        return f"{CPU_LATENCY_DEVICE}: {exc.strerror} (for {what})"
    try:
        os.write(fd, struct.pack("=i", us))
    except OSError as exc:
        os.close(fd)
        return f"{CPU_LATENCY_DEVICE}: {exc.strerror} (for {what})"
    _latency_fd = fd
    return None


def release_cpu_latency() -> None:
    """Drop the request :func:`hold_cpu_latency` holds (nothing if none)."""
    global _latency_fd
    if _latency_fd is not None:
        fd, _latency_fd = _latency_fd, None
        os.close(fd)


def loop_cpus(cpus: list[int] | str | None) -> list[int] | None:
    """``loop.cpus`` as CPUs: ``"last"`` is the highest-numbered CPU this process may run on
    when it may run on two or more (the helpers keep the others), else None (one CPU: the
    loop's SCHED_FIFO preempts them there)."""
    if cpus != "last":
        return cpus  # type: ignore[return-value]
    mine = sorted(os.sched_getaffinity(0))
    return [mine[-1]] if len(mine) >= 2 else None


def setup(
    mode: str, priority: int, cpus: list[int] | str | None, cpu_latency_us: int | None = None
) -> RealtimeReport:
    """Apply ``loop.realtime`` to the calling thread (see module docstring);
    ``cpus``: ``loop.cpus`` (:func:`loop_cpus`); ``cpu_latency_us`` None requests no latency
    limit."""
    rep = RealtimeReport()
    if mode == "off":
        return rep
    if cpus == "last" and loop_cpus(cpus) is None:
        rep.notes.append("loop.cpus: last, but this process may run on one CPU only: not pinned")
    cpus = loop_cpus(cpus)
    for problem in (_try_fifo(priority), _try_mlockall()):
        if problem is not None:
            rep.missing.append(problem)
    if cpu_latency_us is not None:
        problem = hold_cpu_latency(cpu_latency_us)
        if problem is None:
            rep.cpu_latency_us = cpu_latency_us
        else:
            rep.missing.append(problem)
    rep.fifo = os.sched_getscheduler(0) == os.SCHED_FIFO
    rep.locked = not any("mlockall" in m for m in rep.missing)
    if cpus:
        try:
            os.sched_setaffinity(0, cpus)
            rep.cpus = sorted(os.sched_getaffinity(0))
        except OSError as exc:
            rep.missing.append(f"CPU affinity {cpus}: {exc.strerror}")
    if rep.missing and mode == "required":
        release_cpu_latency()
        raise ConfigError(
            "loop.realtime: required, but this process lacks "
            + "; ".join(rep.missing)
            + " (run as the service user with AmbientCapabilities, or set loop.realtime: "
            "preferred)"
        )
    if rep.missing:
        print(
            "hofto-hw: warning: real-time setup incomplete, running without "
            + "; ".join(rep.missing),
            file=sys.stderr,
        )
    return rep


def drop_realtime() -> None:
    """Back to SCHED_OTHER and no CPU latency limit (after the loop, for the slow shutdown
    work, or for the sim clock, which never sleeps)."""
    release_cpu_latency()
    try:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except OSError:
        pass


def cpus_beside_loop() -> list[int] | None:
    """The CPUs a helper process of the loop (the control plane, its planner) should run on:
    those outside the calling loop's affinity when :func:`setup` pinned it to some of them
    (``loop.cpus``) and others are left. None (keep the inherited affinity) when the loop is
    not pinned (it may run anywhere: nothing to keep off), or is pinned to every CPU (one
    CPU: the loop's SCHED_FIFO preempts the helper there, which runs at a nice value)."""
    mine = os.sched_getaffinity(0)
    rest = set(range(os.cpu_count() or 1)) - mine
    if not rest or mine == set(range(os.cpu_count() or 1)):
        return None
    return sorted(rest)


def collect_before_loop() -> None:
    """Collect once and freeze what is left (start-up objects), so the collection that
    :class:`quiet_gc` makes when the loop starts has almost nothing to scan (measured:
    ~0.1-0.2 s for a built system otherwise, time in which the bus carries no process data).
    """
    gc.collect()
    gc.freeze()


class quiet_gc:
    """Context: gc.freeze() + gc.disable() inside, gc.enable() after."""

    def __enter__(self) -> quiet_gc:
        gc.collect()
        gc.freeze()
        gc.disable()
        return self

    def __exit__(self, *exc: object) -> None:
        gc.enable()
        gc.unfreeze()
