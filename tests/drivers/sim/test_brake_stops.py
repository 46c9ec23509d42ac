"""How each stop category ends on an axis with a real, drive-controlled brake."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.cia402 import state_machine as sm
from drivers.cia402.state_machine import Mode, State
from drivers.sim.drive import EmulatedDrives

AXIS = 1
ENGAGE = 0.05


@pytest.fixture
def d(bus) -> EmulatedDrives:
    drives = bus.drives
    drives.configure_brake(AXIS, 0.05, ENGAGE, holding_torque=150.0)
    rx = drives.rx.copy()
    rx["mode"] = Mode.CSP
    drives.step(rx)
    p = drives.plant
    drives.scaling.torque_to_raw(p.true_model.create_data().gravity(p.q_meas), rx["torque_offset"])
    rx["target_position"] = drives.tx["position"]
    for cw in (sm.CW_SHUTDOWN, sm.CW_SWITCH_ON, sm.CW_ENABLE_OPERATION):
        rx["controlword"] = cw
        for _ in range(2):
            drives.step(rx)
    for _ in range(round(0.1 / drives.dt)):
        drives.step(rx)
    assert not drives.brake_engaged[AXIS]
    drives.test_rx = rx  # type: ignore[attr-defined]
    return drives


def _powered(d: EmulatedDrives) -> bool:
    return abs(float(d.plant.tau_applied[AXIS])) > 1.0  # the motor holds the arm's weight


def test_category_1_engages_the_brake_then_removes_power(d) -> None:
    rx = d.test_rx
    rx["controlword"] = sm.CW_QUICK_STOP
    log = []
    for _ in range(round(1.0 / d.dt)):
        d.step(rx)
        log.append((bool(d.brake_engaged[AXIS]), float(d.brake_hold_time[AXIS]) > 0.0))
    assert sm.decode_state(int(d.tx["statusword"][AXIS])) == State.SWITCH_ON_DISABLED
    assert d.brake_engaged[AXIS]
    # the motor kept holding until the brake had engaged: never unbraked and unpowered
    first_engaged = next(k for k, (engaged, _) in enumerate(log) if engaged)
    assert log[first_engaged - 1][1]  # still holding the cycle before
    assert first_engaged > 0


def test_category_0_engages_at_once_and_the_arm_is_free_for_the_engage_delay(d) -> None:
    rx = d.test_rx
    q0 = float(d.plant.q_meas[AXIS])
    rx["controlword"] = sm.CW_DISABLE_VOLTAGE
    d.step(rx)
    assert not _powered(d) and d.brake_hold_time[AXIS] == 0.0
    cycles = 1
    while not d.brake_engaged[AXIS]:
        d.step(rx)
        cycles += 1
    assert cycles * d.dt == pytest.approx(ENGAGE, abs=3 * d.dt)
    assert abs(float(d.plant.q_meas[AXIS]) - q0) > 1e-4  # it dropped until the brake closed


def test_category_2_keeps_power_and_the_brake_open(d) -> None:
    rx = d.test_rx
    rx["target_position"] = d.tx["position"]  # a controlled stop: hold where it is
    for _ in range(round(0.5 / d.dt)):
        d.step(rx)
    assert sm.decode_state(int(d.tx["statusword"][AXIS])) == State.OPERATION_ENABLED
    assert not d.brake_engaged[AXIS] and _powered(d)
    assert np.isfinite(d.plant.q_meas).all()
