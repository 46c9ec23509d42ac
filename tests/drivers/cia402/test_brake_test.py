"""Brake test (drivers/cia402/brake.py) on the emulated drive's master-controlled brake."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.cia402 import state_machine as sm
from drivers.cia402.brake import BrakeTest, brake_test_plan
from drivers.cia402.state_machine import Mode, State
from drivers.sim.drive import EmulatedDrives

AXIS = 1


def _run_test(d: EmulatedDrives, rated: float, fraction: float) -> BrakeTest:
    """Power every drive in CST holding gravity, the shoulder's brake closed (0x60FE bit 0
    low), then the test torque on top of gravity."""
    p = d.plant
    rx = d.rx.copy()
    rx["mode"] = Mode.CST
    d.step(rx)
    gravity = p.true_model.create_data().gravity(p.q_meas).copy()
    d.scaling.torque_to_raw(gravity, rx["target_torque"])
    for cw in (sm.CW_SHUTDOWN, sm.CW_SWITCH_ON, sm.CW_ENABLE_OPERATION):
        rx["controlword"] = cw
        for _ in range(2):
            d.step(rx)
    assert sm.decode_state(int(d.tx["statusword"][AXIS])) == State.OPERATION_ENABLED
    assert d.brake_engaged[AXIS]  # the master has not released it
    test = BrakeTest(brake_test_plan(AXIS, "joint_2", rated, fraction, d.dt))
    tau = gravity.copy()
    while not test.done:
        test.step(float(p.q_meas[AXIS]))
        tau[AXIS] = gravity[AXIS] + test.torque
        d.scaling.torque_to_raw(tau, rx["target_torque"])
        d.step(rx)
    assert d.brake_engaged[AXIS]
    return test


@pytest.fixture
def d(bus) -> EmulatedDrives:
    return bus.drives


def test_a_good_brake_holds_the_test_torque(d) -> None:
    rated = 40.0
    d.configure_brake(AXIS, 0.05, 0.05, holding_torque=rated, by_output=True)
    test = _run_test(d, rated, 0.8)
    assert test.result == "" and abs(test.worst) < 5e-3  # the brake and gearbox compliance


def test_a_worn_brake_fails_the_test(d) -> None:
    rated = 40.0
    d.configure_brake(AXIS, 0.05, 0.05, holding_torque=0.3 * rated, by_output=True)  # worn
    test = _run_test(d, rated, 0.8)
    assert test.result is not None and test.result.startswith("joint_2: the brake slipped")


def test_the_master_releases_a_brake_by_output(d) -> None:
    import struct

    d.configure_brake(AXIS, 0.05, 0.05, holding_torque=40.0, by_output=True)
    _run_test(d, 40.0, 0.1)
    d.ods[AXIS].write(0x60FE, 1, struct.pack("<I", 1))  # bit 0: release
    rx = d.rx.copy()
    for _ in range(round(0.05 / d.dt) + 2):
        d.step(rx)
    assert not d.brake_engaged[AXIS]


def test_fraction_out_of_range_is_refused() -> None:
    with pytest.raises(ValueError, match=r"fraction must be in \(0, 1\]"):
        brake_test_plan(0, "j", 10.0, 1.5, 0.001)
    assert np.isfinite(brake_test_plan(0, "j", 10.0, 0.5, 0.001).torque)
