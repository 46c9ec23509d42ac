"""Safe torque off at enable: a clear state naming the axis, not a timeout or a fault."""

from __future__ import annotations

import pytest

from drivers.cia402 import state_machine as sm
from drivers.cia402.drive_group import DriveError, DriveGroup, DriveTimeoutError
from drivers.cia402.state_machine import Mode, State
from drivers.sim.simbus import SimBus


@pytest.fixture
def group(bus: SimBus, cfg) -> DriveGroup:
    bus.open()
    g = DriveGroup.from_config(bus, cfg.bus)
    g.configure(cfg.bus.drives)
    g.set_mode(Mode.CSP)
    return g


def test_boot_with_sto_active_is_one_line_naming_the_axis(group, bus) -> None:
    bus.drives.set_safe_torque_off(3, True)
    with pytest.raises(DriveError) as info:
        group.enable()
    assert not isinstance(info.value, DriveTimeoutError)
    msg = str(info.value)
    assert msg.startswith(f"axis 3 ({group.names[3]}): safe torque off is active")
    assert "\n" not in msg
    assert not group.any_fault()  # a state, not a fault
    bus.drives.set_safe_torque_off(3, False)  # released: enabling works
    group.enable()
    assert group.all_in(State.OPERATION_ENABLED)


def test_sto_while_enabling_stops_enabling_naming_the_axis(group, bus) -> None:
    """STO asserted after the check, while the drives are being enabled: the defined outcome
    is every drive commanded to disable voltage and one line naming the axis, at once."""
    real_cycle = group.cycle
    calls = {"n": 0}

    def cycle() -> int:
        calls["n"] += 1
        if calls["n"] == 2:
            bus.drives.set_safe_torque_off(1, True)
        return real_cycle()

    group.cycle = cycle  # type: ignore[method-assign]
    with pytest.raises(
        DriveError,
        match=r"^axis 1 \(joint_2\): safe torque off became active "
        r"while enabling \(0x60FD:00 bit 16\)",
    ) as info:
        group.enable()
    assert not isinstance(info.value, DriveTimeoutError)
    assert (group.transport.rx["controlword"] == sm.CW_DISABLE_VOLTAGE).all()
    assert calls["n"] < 2 + group.timeout_cycles  # at once, not at the timeout
