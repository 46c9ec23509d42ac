"""hofto_hw.runtime.realtime: the CPU wake-up latency limit (loop.cpu_latency_us) is a PM QoS
request held open while the loop runs, given back by drop_realtime and on a refusal; a device
that cannot be written is one line naming it (a warning, or the refusal under required)."""

from __future__ import annotations

import os
import struct
import time
from pathlib import Path

import pytest

from hofto_hw.errors import ConfigError
from hofto_hw.runtime import realtime
from tests.support.pm_qos import kernel_cpu_latency, require_latency_device


def _open_to(path: Path) -> int:
    """How many file descriptors this process has open on ``path``."""
    fds = Path("/proc/self/fd")
    return sum(os.path.realpath(fds / n) == str(path) for n in os.listdir(fds))


@pytest.fixture
def device(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A regular file standing in for /dev/cpu_dma_latency; FIFO and mlockall not touched
    (the test process must not become real-time)."""
    dev = tmp_path / "cpu_dma_latency"
    dev.write_bytes(b"")
    monkeypatch.setattr(realtime, "CPU_LATENCY_DEVICE", str(dev))
    monkeypatch.setattr(realtime, "_try_fifo", lambda priority: None)
    monkeypatch.setattr(realtime, "_try_mlockall", lambda: None)
    yield dev
    realtime.release_cpu_latency()


def test_setup_holds_the_limit_until_drop_realtime(device: Path) -> None:
    rep = realtime.setup("required", 50, None, 7)
    assert rep.cpu_latency_us == 7 and rep.missing == []
    assert device.read_bytes() == struct.pack("=i", 7)  # the kernel's 4-byte request [µs]
    assert _open_to(device) == 1
    assert "CPU wake-up latency <= 7 µs" in rep.describe()
    realtime.drop_realtime()
    assert not _open_to(device)


def test_a_second_hold_replaces_the_first(device: Path) -> None:
    assert realtime.hold_cpu_latency(5) is None
    assert realtime.hold_cpu_latency(0) is None
    assert _open_to(device) == 1 and device.read_bytes() == struct.pack("=i", 0)


def test_no_limit_requested_or_realtime_off_opens_nothing(device: Path) -> None:
    assert realtime.setup("preferred", 50, None, None).cpu_latency_us is None
    assert realtime.setup("off", 50, None, 0).cpu_latency_us is None
    assert not _open_to(device) and device.read_bytes() == b""


def test_missing_device_is_one_warning_line_under_preferred(
    device: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    gone = device.parent / "absent" / "cpu_dma_latency"
    monkeypatch.setattr(realtime, "CPU_LATENCY_DEVICE", str(gone))
    rep = realtime.setup("preferred", 50, None, 0)
    assert rep.cpu_latency_us is None
    assert len(rep.missing) == 1 and str(gone) in rep.missing[0]
    assert "No such file or directory" in rep.missing[0]
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "real-time setup incomplete" in err[0] and str(gone) in err[0]


def test_unwritable_device_refuses_under_required_naming_it_and_the_udev_rule(
    device: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def denied(path: str, flags: int, *args: object) -> int:
        raise PermissionError(13, "Permission denied", path)

    monkeypatch.setattr(realtime.os, "open", denied)
    with pytest.raises(ConfigError) as exc:
        realtime.setup("required", 50, None, 0)
    msg = str(exc.value)
    assert "\n" not in msg and "loop.realtime: required" in msg
    assert f"write access to {device}" in msg and "60-hofto-hw-cpu-latency.rules" in msg


def test_a_refusal_gives_the_held_limit_back(device: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(realtime, "_try_fifo", lambda priority: "CAP_SYS_NICE for SCHED_FIFO")
    with pytest.raises(ConfigError, match="CAP_SYS_NICE"):
        realtime.setup("required", 50, None, 0)
    assert device.read_bytes() == struct.pack("=i", 0)  # it was taken ...
    assert not _open_to(device)  # ... and given back with the refusal


def test_the_kernel_applies_the_request_while_held() -> None:
    require_latency_device()
    before = kernel_cpu_latency()
    assert realtime.hold_cpu_latency(123) is None
    try:
        assert kernel_cpu_latency() == min(before, 123)
    finally:
        realtime.release_cpu_latency()
    assert kernel_cpu_latency() == before


def test_sleep_until_a_passed_deadline_makes_no_system_call(monkeypatch) -> None:
    calls = []
    real = realtime._clock_nanosleep
    monkeypatch.setattr(realtime, "_clock_nanosleep", lambda *a: calls.append(a[:2]) or real(*a))
    realtime.sleep_until(time.monotonic_ns() - 1)
    assert calls == []
    deadline = time.monotonic_ns() + 2_000_000
    realtime.sleep_until(deadline)
    assert calls == [(realtime.CLOCK_MONOTONIC, realtime.TIMER_ABSTIME)]
    assert time.monotonic_ns() >= deadline  # absolute: never early


def test_loop_cpus_last_is_the_highest_cpu_of_two_or_more_else_left_alone(monkeypatch) -> None:
    monkeypatch.setattr(realtime.os, "sched_getaffinity", lambda pid: {0, 1, 3})
    assert realtime.loop_cpus("last") == [3]
    assert realtime.loop_cpus([0]) == [0] and realtime.loop_cpus(None) is None
    monkeypatch.setattr(realtime.os, "sched_getaffinity", lambda pid: {2})
    assert realtime.loop_cpus("last") is None  # one CPU: the helpers share it, said by setup


def test_loop_cpus_last_is_accepted_by_the_config_and_a_word_else_is_refused(tmp_path) -> None:
    import yaml

    from hofto_hw.config.loader import load_config

    src = Path(__file__).resolve().parents[3] / "configs" / "er3a_service.yaml"
    cfg = load_config(src)
    assert cfg.loop.cpus == "last"
    data = yaml.safe_load(src.read_text())
    data["robot"]["urdf"] = str((src.parent / data["robot"]["urdf"]).resolve())
    data["loop"]["cpus"] = "first"
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError) as err:
        load_config(bad)
    assert "loop.cpus" in str(err.value) and "\n" not in str(err.value)
