"""Safe torque off while the loop runs: a category 0 event naming the axis, latched; the
arm is enabled again only by an explicit reset after STO is released (issue 28)."""

from __future__ import annotations

from drivers.cia402.state_machine import CW_DISABLE_VOLTAGE, State
from hofto_hw.config.models import SystemConfig
from safety.stop import Fault
from tests.hofto_hw.runtime.conftest import run_until
from tests.hofto_hw.runtime.test_faults import _moving


def test_sto_while_running_is_category_0_naming_the_axis(cfg: SystemConfig) -> None:
    system = _moving(cfg)
    tick, stop = system.tick, system.tick.stop
    system.bus.drives.set_safe_torque_off(4, True)
    run_until(system, lambda: stop.latched != 0, 200)
    assert stop.latched_names() == ["sto"]  # its own class, not drive_disabled
    assert stop.category == 0 == cfg.safety.categories.sto
    ev = system.sink.last_events()
    mine = ev[ev["kind"] == int(Fault.STO)]
    assert len(mine) == 1 and mine["joint"][0] == 4 and mine["category"][0] == 0
    tick.reset_requested = True  # a reset while STO is still active is refused
    system.loop.run(max_ticks=30)
    assert tick.reset_result == f"reset refused, safe torque off active: {system.group.names[4]}"
    assert stop.is_latched(Fault.STO)
    # released: nothing re-enables by itself
    system.bus.drives.set_safe_torque_off(4, False)
    system.loop.run(max_ticks=100)
    assert stop.is_latched(Fault.STO)
    assert not system.group.all_in(State.OPERATION_ENABLED)
    tick.reset_requested = True  # the explicit reset
    system.loop.run(max_ticks=30)
    assert stop.latched == 0, tick.reset_result
    run_until(system, lambda: tick.expect_enabled, 500)
    assert system.group.all_in(State.OPERATION_ENABLED)


def test_sto_toggling_during_the_re_enable_latches_sto_at_once(cfg: SystemConfig) -> None:
    """STO asserted while the loop walks the drives back to Operation enabled after a reset:
    the defined outcome is STO latched naming the axis, category 0 commanded in that tick."""
    system = _moving(cfg)
    tick, stop = system.tick, system.tick.stop
    system.tick.stop_requested = True
    run_until(system, lambda: stop.latched != 0, 200)
    run_until(system, lambda: not system.group.all_in(State.OPERATION_ENABLED), 3000)
    tick.stop_requested = False
    system.loop.run(max_ticks=5)
    tick.reset_requested = True
    run_until(system, lambda: tick.enabling, 50)
    system.bus.drives.set_safe_torque_off(2, True)
    run_until(system, lambda: stop.latched != 0, 50)
    assert stop.latched_names() == ["sto"] and stop.category == 0
    assert not tick.enabling
    assert (system.bus.rx["controlword"] == CW_DISABLE_VOLTAGE).all()  # the same tick
    ev = system.sink.last_events()
    assert ev[ev["kind"] == int(Fault.STO)]["joint"].tolist() == [2]
