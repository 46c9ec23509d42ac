"""The kernel's PM QoS CPU latency limit, read as the tests of loop.cpu_latency_us need it."""

from __future__ import annotations

import os
import struct
import time

import pytest

from hofto_hw.runtime.realtime import CPU_LATENCY_DEVICE
from tests.support.rootnet import require_root


def require_latency_device() -> None:
    """Skip unless root and the device exists; under CI (env CI set) fail instead."""
    require_root(f"the PM QoS device {CPU_LATENCY_DEVICE}")
    if not os.path.exists(CPU_LATENCY_DEVICE):
        if os.environ.get("CI"):
            pytest.fail(f"CI is set but {CPU_LATENCY_DEVICE} does not exist")
        pytest.skip(f"{CPU_LATENCY_DEVICE} does not exist (kernel without PM QoS)")


def kernel_cpu_latency() -> int:
    """The limit [µs] the kernel applies now (the smallest request held by any process)."""
    fd = os.open(CPU_LATENCY_DEVICE, os.O_RDONLY)
    try:
        return struct.unpack("=i", os.read(fd, 4))[0]
    finally:
        os.close(fd)


def latency_holders() -> list[str]:
    """The processes that hold the CPU latency device open now ("pid command")."""
    real = os.path.realpath(CPU_LATENCY_DEVICE)
    out = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            fds = os.listdir(f"/proc/{pid}/fd")
            if any(os.path.realpath(f"/proc/{pid}/fd/{fd}") == real for fd in fds):
                with open(f"/proc/{pid}/cmdline", "rb") as f:
                    cmd = f.read().replace(b"\0", b" ").decode(errors="replace").strip()
                out.append(f"{pid} {cmd[:120]}")
        except OSError:  # gone meanwhile, or not ours to read
            continue
    return out


def latency_free_above(limit_us: int, timeout: float = 180.0) -> int:
    """Wait until no process holds a limit of ``limit_us`` or less (another run's service on
    this shared machine lets go when it ends), at most ``timeout`` [s]; the kernel's limit
    then. Under CI a holder that stays is a failure naming it, else a skip."""
    deadline = time.monotonic() + timeout
    while (now := kernel_cpu_latency()) <= limit_us:
        if time.monotonic() >= deadline:
            why = (
                f"another process holds a CPU latency limit of {now} µs for more than "
                f"{timeout:.0f} s: {'; '.join(latency_holders()) or 'holder not found'}"
            )
            if os.environ.get("CI"):
                pytest.fail(why)
            pytest.skip(why)
        time.sleep(0.2)
    return now
