"""Flight-recorder failure is a reported fault (LOG_FAILURE) that never stops the loop by
itself; with ``safety.categories.log_failure: 1`` the arm stops."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import pytest

from hofto_hw.recording.flight_file import LogSpec
from hofto_hw.recording.recorder import FlightRecorder
from hofto_hw.runtime.compose import build, loop_observer_names
from hofto_hw.runtime.log_watch import LogWatch
from safety.stop import Fault
from tests.hofto_hw.runtime.conftest import run_until, with_updates


def _wait(pred, what: str, limit: float = 120.0) -> None:
    end = time.monotonic() + limit
    while not pred():
        assert time.monotonic() < end, f"never reached: {what}"
        time.sleep(0.01)


def _system(cfg, path: Path, **spec_kw):
    names = loop_observer_names(cfg)
    rec = FlightRecorder(LogSpec(path, list(cfg.robot.joints), names, **spec_kw)).start()
    return build(cfg, clock="sim", sink=rec, contact=False), rec


def _latched(system) -> bool:
    return system.tick.stop.is_latched(Fault.LOG_FAILURE)


@pytest.mark.parametrize("category", [None, 1])
def test_dead_writer_is_a_log_failure_fault_of_the_configured_category(cfg, tmp_path, category):
    cats = cfg.safety.categories.model_copy(update={"log_failure": category})
    c = with_updates(cfg, "safety", categories=cats)
    system, rec = _system(c, tmp_path / "run.mcap")
    try:
        watch = LogWatch(rec, system.tick)
        run_until(system, lambda: system.loop.ticks >= 50, 100)
        assert not watch.check() and not _latched(system)  # a healthy log is no fault
        os.kill(rec.writer_pid, signal.SIGKILL)
        _wait(lambda: not rec.health().writer_alive, "writer seen dead")
        assert watch.check() and "writer process dead" in watch.reason
        run_until(system, lambda: _latched(system), 5)
        ev = system.tick.stop.events
        kinds = [int(ev.kind[i]) for i in range(ev.count)]
        assert kinds.count(int(Fault.LOG_FAILURE)) == 1
        if category is None:  # report only: the loop and the arm go on
            before = system.loop.ticks
            run_until(system, lambda: system.loop.ticks >= before + 500, 600)
            assert system.tick.stop.category == -1 and not system.tick.stopped_and_off()
        else:
            assert system.tick.stop.category == 1
            run_until(system, system.tick.stopped_and_off, 5000)
    finally:
        system.close()
        rec.close()


def test_full_disk_reaches_the_loop_through_the_watch_thread(cfg, tmp_path):
    system, rec = _system(cfg, tmp_path / "run.mcap", fail_after_bytes=100_000)
    watch = LogWatch(rec, system.tick, interval=0.01).start()
    try:
        # the loop runs until the thread has seen the failing disk and the tick reported it
        run_until(system, lambda: _latched(system), 2_000_000)
        assert "disk failing" in watch.reason or "records" in watch.reason
        assert system.tick.stop.category == -1  # the default: report only
        before = system.loop.ticks
        run_until(system, lambda: system.loop.ticks >= before + 200, 300)
    finally:
        watch.stop()
        system.close()
        rec.close()
