"""Each fault through the whole loop ends in its configured stop category, latched, in the
events; reset refuses while the cause persists."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from drivers.cia402 import state_machine as sm
from drivers.cia402.state_machine import State
from hofto_hw.config.models import SystemConfig
from hofto_hw.control.joint_motion import MOVE
from hofto_hw.recording.record import MemorySink, tick_dtype
from hofto_hw.runtime.compose import build
from safety.stop import Fault
from tests.hofto_hw.runtime.conftest import run_until
from tests.support.reference_tick import use_reference

CONTROLWORD = {0: sm.CW_DISABLE_VOLTAGE, 1: sm.CW_QUICK_STOP}


def _moving(cfg: SystemConfig) -> Any:
    system = build(
        cfg, clock="sim", contact=False, sink=MemorySink(tick_dtype(6, 2), capacity=4096)
    )
    system.tick.mode_request = MOVE
    system.loop.run(max_ticks=1500)
    assert system.tick.stop.latched == 0
    return system


def _corrupt_once(system: Any, change: Callable[[Any], None]) -> None:
    """Make the next decoded sample wrong once (the group decodes in read())."""
    g = system.group
    use_reference(system)  # the compiled call reads the images itself, not through g.read
    original = g.read

    def read() -> None:
        original()
        change(g)
        g.read = original

    g.read = read


def _check(system: Any, fault: Fault, category: int) -> None:
    tick, stop = system.tick, system.tick.stop
    run_until(system, lambda: stop.latched != 0, 200)
    assert stop.is_latched(fault), stop.latched_names()
    assert stop.category == category
    if category in CONTROLWORD:
        assert (system.bus.rx["controlword"] == CONTROLWORD[category]).all()
    events = system.sink.last_events()
    mine = events[events["kind"] == int(fault)]
    assert len(mine) == 1 and mine["category"][0] == category
    # latched: it stays after more ticks
    system.loop.run(max_ticks=50)
    assert stop.is_latched(fault) and tick.category() <= category


def test_bus_drop_streak_is_bus_loss(cfg: SystemConfig) -> None:
    system = _moving(cfg)
    system.bus.drop_cycles(cfg.safety.bus.lost_cycles + 2)
    _check(system, Fault.BUS_LOSS, cfg.safety.categories.bus_loss)


def test_drive_fault_is_reported_with_its_code(cfg: SystemConfig) -> None:
    system = _moving(cfg)
    system.bus.inject_fault(2, "over_temperature")
    _check(system, Fault.DRIVE_FAULT, cfg.safety.categories.drive_fault)
    ev = system.sink.last_events()
    mine = ev[ev["kind"] == int(Fault.DRIVE_FAULT)]
    assert mine["joint"][0] == 2 and int(mine["value"][0]) == 0x4310


def test_overrun_streak(cfg: SystemConfig) -> None:
    system = _moving(cfg)
    system.clock.stall(cfg.safety.overrun_streak - 1)  # one short of the streak: no fault
    system.loop.run(max_ticks=5)
    assert not system.tick.stop.is_latched(Fault.OVERRUN)
    system.clock.stall(cfg.safety.overrun_streak + 5)
    _check(system, Fault.OVERRUN, cfg.safety.categories.overrun)
    assert system.tick.overruns == 2 * cfg.safety.overrun_streak + 4


def test_nan_in_measurement(cfg: SystemConfig) -> None:
    system = _moving(cfg)
    _corrupt_once(system, lambda g: g.qd.__setitem__(4, np.nan))
    _check(system, Fault.NON_FINITE, cfg.safety.categories.non_finite)
    ev = system.sink.last_events()
    assert ev[ev["kind"] == int(Fault.NON_FINITE)]["joint"][0] == 4


def test_nan_from_the_model(cfg: SystemConfig) -> None:
    system = _moving(cfg)
    use_reference(system)  # the compiled call runs the bank's kernel, not bank.update
    bank = system.tick._bank  # the tick's observers write their rows of tau_ext through it
    original = bank.update

    def update(dt: float) -> None:
        bank.update = original
        original(dt)
        system.tick.tau_ext[1].fill(np.nan)  # observer 1's estimate turns non-finite, once

    bank.update = update
    _check(system, Fault.NON_FINITE, cfg.safety.categories.non_finite)


def test_position_jump(cfg: SystemConfig) -> None:
    system = _moving(cfg)
    _corrupt_once(system, lambda g: g.q.__setitem__(3, g.q[3] + 0.1))
    _check(system, Fault.POSITION_JUMP, cfg.safety.categories.position_jump)


def test_stop_request(cfg: SystemConfig) -> None:
    system = _moving(cfg)
    system.tick.stop_requested = True
    _check(system, Fault.STOP_REQUEST, cfg.safety.categories.stop_request)
    run_until(system, system.tick.stopped_and_off, 3000)
    assert not (system.group.states == State.OPERATION_ENABLED).any()


def test_reset_refuses_while_the_cause_persists_then_reenables(cfg: SystemConfig) -> None:
    system = _moving(cfg)
    tick, stop = system.tick, system.tick.stop
    system.bus.inject_fault(0, "encoder", persistent=True)
    run_until(system, lambda: stop.latched != 0, 100)
    system.loop.run(max_ticks=20)
    tick.reset_requested = True
    system.loop.run(max_ticks=30)  # fault-reset edges first, then the verdict
    assert tick.reset_result == "reset refused, cause still present: drive_fault"
    assert stop.is_latched(Fault.DRIVE_FAULT)
    # the cause goes away: reset clears, the drives are enabled again (fault-reset edge)
    system.bus.drives.clear_fault(0)
    tick.reset_requested = True
    system.loop.run(max_ticks=30)
    assert tick.reset_result.startswith("reset: drive_fault")
    assert stop.latched == 0
    run_until(system, lambda: tick.expect_enabled, 500)
    assert system.group.all_in(State.OPERATION_ENABLED)
    system.loop.run(max_ticks=200)
    assert stop.latched == 0, stop.latched_names()


@pytest.mark.parametrize("category", [0, 1, 2])
def test_each_category_is_acted(cfg: SystemConfig, category: int) -> None:
    cats = cfg.safety.categories.model_copy(update={"stop_request": category})
    c2 = cfg.model_copy(update={"safety": cfg.safety.model_copy(update={"categories": cats})})
    system = _moving(c2)
    system.tick.stop_requested = True
    _check(system, Fault.STOP_REQUEST, category)
    system.loop.run(max_ticks=1500)
    assert np.abs(system.group.qd).max() < 0.05  # at rest in every category
    powered = system.group.all_in(State.OPERATION_ENABLED)
    assert powered == (category == 2)
