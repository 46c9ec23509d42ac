"""CiA 402 homing (mode 6): the emulated drive's two methods and the stack's sequence."""

from __future__ import annotations

import struct

import pytest

from drivers.cia402 import state_machine as sm
from drivers.cia402.homing import HomingSequence, homing_plan
from drivers.cia402.state_machine import Mode, State
from drivers.sim.drive import EmulatedDrives
from drivers.sim.simbus import SimBus
from hofto_hw.config.drives import HomingConfig

PACK = {"i8": "<b", "u32": "<I", "i32": "<i"}
AXIS = 2


@pytest.fixture
def drives(bus: SimBus) -> EmulatedDrives:
    d = bus.drives
    rx = d.rx.copy()
    rx["mode"] = Mode.CSP
    d.step(rx)
    rx["target_position"] = d.tx["position"]
    for cw in (sm.CW_SHUTDOWN, sm.CW_SWITCH_ON, sm.CW_ENABLE_OPERATION):
        rx["controlword"] = cw
        for _ in range(2):
            d.step(rx)
    assert all(sm.decode_state(int(w)) == State.OPERATION_ENABLED for w in d.tx["statusword"])
    return d


def _position(d: EmulatedDrives, axis: int) -> float:
    return float(
        d.scaling.rad_per_count[axis] * (int(d.tx["position"][axis]) - d.scaling.zero_offset[axis])
    )


def _home(d: EmulatedDrives, cfg: HomingConfig, max_cycles: int = 20000) -> tuple[str, int]:
    """Write the plan by SDO, step the sequence to its end holding the other axes; the
    result and the cycles it took."""
    plan = homing_plan(cfg, d.scaling, AXIS, d.dt, name="joint_3")
    for index, sub, kind, value in plan.sdo_writes():
        d.ods[AXIS].write(index, sub, struct.pack(PACK[kind], value))
    seq = HomingSequence(plan)
    rx = d.rx.copy()
    for k in range(max_cycles):
        rx["controlword"][AXIS] = seq.controlword
        rx["mode"][AXIS] = seq.mode
        rx["target_position"][AXIS] = d.tx["position"][AXIS]  # CSP holds where it is
        d.step(rx)
        seq.step(int(d.tx["statusword"][AXIS]), int(d.tx["mode_display"][AXIS]), _position(d, AXIS))
        if seq.done:
            assert seq.result is not None
            return seq.result, k + 1
    raise AssertionError("the homing sequence never ended")


def test_method_35_makes_the_current_position_the_home_offset(drives) -> None:
    q_true = float(drives.plant.q_meas[AXIS])
    cfg = HomingConfig(method=35, speeds=(0.2, 0.02), acceleration=2.0, offset=0.5, timeout=1.0)
    result, _ = _home(drives, cfg)
    assert result == ""
    assert _position(drives, AXIS) == pytest.approx(0.5, abs=1e-3)
    assert float(drives.plant.q_meas[AXIS]) == pytest.approx(q_true, abs=1e-3)  # did not move
    assert int(drives.tx["mode_display"][AXIS]) == Mode.CSP  # back in the loop's mode
    # CSP targets are taken in the new reference: holding the reported position holds still
    rx = drives.rx.copy()
    rx["target_position"] = drives.tx["position"]
    for _ in range(200):
        drives.step(rx)
    assert float(drives.plant.q_meas[AXIS]) == pytest.approx(q_true, abs=2e-3)


def test_method_17_finds_the_switch_edge(drives) -> None:
    q0 = float(drives.plant.q_meas[AXIS])
    switch = q0 - 0.05  # the switch edge 50 mrad below the start
    drives.set_home_switch(AXIS, switch)
    cfg = HomingConfig(method=17, speeds=(0.2, 0.02), acceleration=2.0, offset=-0.3, timeout=5.0)
    result, cycles = _home(drives, cfg)
    assert result == ""
    # the edge is where the drive now reads the offset; the arm stopped just past it
    true_now = float(drives.plant.q_meas[AXIS])
    assert true_now == pytest.approx(switch, abs=0.005)
    assert _position(drives, AXIS) - true_now == pytest.approx(-0.3 - switch, abs=0.002)
    assert cycles * drives.dt > 0.05 / 0.2  # it searched, at most at the switch speed


def test_homing_that_does_not_finish_in_time_is_reported(drives) -> None:
    drives.set_home_switch(AXIS, float(drives.plant.q_meas[AXIS]) - 0.5)
    cfg = HomingConfig(method=17, speeds=(0.05, 0.01), acceleration=1.0, timeout=0.5)
    result, _ = _home(drives, cfg)
    assert result.startswith("joint_3: homing (method 17) did not end within")
    assert int(drives.tx["mode_display"][AXIS]) == Mode.CSP


def test_no_switch_ends_in_homing_error(drives) -> None:
    drives.homing_travel[AXIS] = 0.05
    cfg = HomingConfig(method=17, speeds=(0.2, 0.02), acceleration=2.0, timeout=5.0)
    result, _ = _home(drives, cfg)
    assert result.startswith("joint_3: the drive reports homing error (method 17)")


def test_unexpected_end_position_is_reported(drives) -> None:
    """The drive ends homing away from the offset (here: its 0x607C changed after the
    plan was written): the sequence says where it ended and by how much."""
    cfg = HomingConfig(method=35, speeds=(0.2, 0.02), acceleration=2.0, offset=0.2, timeout=1.0)
    plan = homing_plan(cfg, drives.scaling, AXIS, drives.dt, name="joint_3")
    for index, sub, kind, value in plan.sdo_writes():
        drives.ods[AXIS].write(index, sub, struct.pack(PACK[kind], value))
    drives.ods[AXIS].write(0x607C, 0, struct.pack("<i", plan.home_offset + 100000))
    seq = HomingSequence(plan)
    rx = drives.rx.copy()
    while not seq.done:
        rx["controlword"][AXIS], rx["mode"][AXIS] = seq.controlword, seq.mode
        rx["target_position"][AXIS] = drives.tx["position"][AXIS]
        drives.step(rx)
        seq.step(
            int(drives.tx["statusword"][AXIS]),
            int(drives.tx["mode_display"][AXIS]),
            _position(drives, AXIS),
        )
    assert seq.result is not None and "joint_3: homing ended at" in seq.result
    assert "from the home offset 0.2000 rad" in seq.result


def test_homing_config_none_is_an_absolute_axis() -> None:
    from hofto_hw.config.drives import DriveConfig

    base = dict(
        counts_per_rev=131072,
        gear_ratio=100.0,
        rated_torque=640,
        rated_current=2800,
        torque_constant=0.2,
        torque_limit=100.0,
        quick_stop_deceleration=10.0,
    )
    assert DriveConfig(**base, homing="none").homing is None
    with pytest.raises(ValueError, match="method 0 is 'no homing'"):
        DriveConfig(**base, homing=dict(method=0, speeds=[0.1, 0.01], acceleration=1, timeout=1))


@pytest.mark.parametrize(("method", "direction"), [(33, -1.0), (34, 1.0)])
def test_methods_33_34_home_on_the_next_index_pulse(drives, method, direction) -> None:
    q0 = float(drives.plant.q_meas[AXIS])
    pitch = float(drives.index_pitch[AXIS])  # one motor turn at the joint
    drives.set_index_phase(AXIS, q0 + 0.4 * pitch)  # pulses at q0 + 0.4·pitch + k·pitch
    pulse = q0 + 0.4 * pitch if direction > 0 else q0 - 0.6 * pitch
    cfg = HomingConfig(method=method, speeds=(0.2, 0.05), acceleration=2.0, offset=0.2,
                       timeout=5.0)  # fmt: skip
    result, _ = _home(drives, cfg)
    assert result == ""
    true_now = float(drives.plant.q_meas[AXIS])
    assert (true_now - q0) * direction > 0  # it went the method's way
    # the pulse's own position is home: reported - offset = true - pulse
    assert _position(drives, AXIS) - 0.2 == pytest.approx(true_now - pulse, abs=2e-4)


def test_method_2_searches_the_positive_limit_then_the_index_below(drives) -> None:
    q0 = float(drives.plant.q_meas[AXIS])
    pitch = float(drives.index_pitch[AXIS])
    drives.set_home_switch(AXIS, q0 + 0.03, positive=True)
    drives.set_index_phase(AXIS, q0 + 0.03 - 0.25 * pitch)  # the first pulse below the edge
    cfg = HomingConfig(method=2, speeds=(0.2, 0.05), acceleration=2.0, offset=0.0, timeout=5.0)
    result, _ = _home(drives, cfg)
    assert result == ""
    true_now = float(drives.plant.q_meas[AXIS])
    pulse = q0 + 0.03 - 0.25 * pitch
    assert _position(drives, AXIS) == pytest.approx(true_now - pulse, abs=2e-4)


def test_no_index_pulse_within_the_travel_ends_in_homing_error(drives) -> None:
    drives.homing_travel[AXIS] = 0.2 * float(drives.index_pitch[AXIS])
    drives.set_index_phase(AXIS, float(drives.plant.q_meas[AXIS]) + 0.5 * drives.index_pitch[AXIS])
    cfg = HomingConfig(method=34, speeds=(0.2, 0.05), acceleration=2.0, timeout=5.0)
    result, _ = _home(drives, cfg)
    assert result.startswith("joint_3: the drive reports homing error (method 34)")
