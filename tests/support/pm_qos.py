"""The kernel's PM QoS CPU latency limit, read as the tests of loop.cpu_latency_us need it."""

from __future__ import annotations

import os
import struct

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
