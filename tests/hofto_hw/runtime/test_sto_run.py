"""Safe torque off while the loop runs: a category 0 event naming the axis, latched; the
arm is enabled again only by an explicit reset after STO is released (issue 28)."""

from __future__ import annotations

from drivers.cia402.state_machine import State
from hofto_hw.config.models import SystemConfig
from safety.stop import Fault
from tests.hofto_hw.runtime.conftest import run_until
from tests.hofto_hw.runtime.test_faults import _moving


def test_sto_while_running_is_category_0_naming_the_axis(cfg: SystemConfig) -> None:
    system = _moving(cfg)
    tick, stop = system.tick, system.tick.stop
    system.bus.drives.set_safe_torque_off(4, True)
    run_until(system, lambda: stop.latched != 0, 200)
    assert stop.is_latched(Fault.DRIVE_DISABLED), stop.latched_names()
    assert stop.category == 0 == cfg.safety.categories.drive_disabled
    ev = system.sink.last_events()
    mine = ev[ev["kind"] == int(Fault.DRIVE_DISABLED)]
    assert len(mine) == 1 and mine["joint"][0] == 4
    tick.reset_requested = True  # a reset while STO is still active is refused
    system.loop.run(max_ticks=30)
    assert tick.reset_result == f"reset refused, safe torque off active: {system.group.names[4]}"
    assert stop.is_latched(Fault.DRIVE_DISABLED)
    # released: nothing re-enables by itself
    system.bus.drives.set_safe_torque_off(4, False)
    system.loop.run(max_ticks=100)
    assert stop.is_latched(Fault.DRIVE_DISABLED)
    assert not system.group.all_in(State.OPERATION_ENABLED)
    tick.reset_requested = True  # the explicit reset
    system.loop.run(max_ticks=30)
    assert stop.latched == 0, tick.reset_result
    run_until(system, lambda: tick.expect_enabled, 500)
    assert system.group.all_in(State.OPERATION_ENABLED)
