"""Emulated CiA-402 drives driven directly at the process-image level (raw units)."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from drivers.cia402 import state_machine as sm
from drivers.cia402.state_machine import Mode, State
from drivers.sim.drive import EmulatedDrives
from drivers.sim.simbus import SimBus


@pytest.fixture
def drives(bus: SimBus) -> EmulatedDrives:
    return bus.drives


def _states(d: EmulatedDrives) -> list[State]:
    return [sm.decode_state(int(w)) for w in d.tx["statusword"]]


def _run(d: EmulatedDrives, rx: np.ndarray, cycles: int, cw: int | None = None) -> None:
    if cw is not None:
        rx["controlword"] = cw
    for _ in range(cycles):
        d.step(rx)


def _enable(d: EmulatedDrives, rx: np.ndarray, mode: Mode) -> None:
    rx["mode"] = mode
    rx["target_position"] = d.tx["position"]
    for cw in (sm.CW_SHUTDOWN, sm.CW_SWITCH_ON, sm.CW_ENABLE_OPERATION):
        _run(d, rx, 2, cw)
    assert _states(d) == [State.OPERATION_ENABLED] * 6


def test_power_up_reports_not_ready_then_switch_on_disabled(drives: EmulatedDrives) -> None:
    assert _states(drives) == [State.NOT_READY_TO_SWITCH_ON] * 6
    rx = drives.rx.copy()
    drives.step(rx)
    assert _states(drives) == [State.SWITCH_ON_DISABLED] * 6
    assert all(drives.tx["statusword"] == 0x0240)  # state bits + remote


def test_encoder_counts_come_from_the_plant(drives: EmulatedDrives) -> None:
    p = drives.plant
    expected = np.rint(p.q_meas * drives.scaling.count_per_rad + drives.scaling.zero_offset)
    assert np.array_equal(drives.tx["position"], expected.astype(np.int32))


def test_torque_limit_clips_and_sets_internal_limit_bit(drives: EmulatedDrives) -> None:
    rx = drives.rx.copy()
    _run(drives, rx, 1)
    _enable(drives, rx, Mode.CST)
    rx["target_torque"] = 30000  # far above 0x6072
    drives.step(rx)
    limit = drives.max_torque * np.abs(drives.scaling.nm_per_permille)
    assert np.allclose(np.abs(drives.plant.tau_applied), limit)
    assert all(drives.tx["statusword"] & sm.SW_INTERNAL_LIMIT)
    # Lowering 0x6072 by SDO lowers the torque the drive applies.
    drives.ods[0].write(0x6072, 0, struct.pack("<H", 100))
    drives.step(rx)
    assert abs(drives.plant.tau_applied[0]) == pytest.approx(
        100 * abs(drives.scaling.nm_per_permille[0])
    )


def test_torque_offset_adds_in_cst(drives: EmulatedDrives) -> None:
    rx = drives.rx.copy()
    _run(drives, rx, 1)
    _enable(drives, rx, Mode.CST)
    rx["target_torque"] = 100
    rx["torque_offset"] = 50
    drives.step(rx)
    assert np.allclose(drives.plant.tau_applied, 150 * drives.scaling.nm_per_permille)


def test_fault_reset_needs_a_new_rising_edge(drives: EmulatedDrives) -> None:
    rx = drives.rx.copy()
    _run(drives, rx, 1)
    _enable(drives, rx, Mode.CSP)
    drives.inject_fault(5, "over_current")
    _run(drives, rx, 3, sm.CW_FAULT_RESET)  # bit 7 rises BEFORE the fault occurs ...
    _run(drives, rx, 5)  # ... and stays high: no new edge, the fault stays latched
    assert _states(drives)[5] == State.FAULT
    assert drives.tx["error_code"][5] == 0x2310
    _run(drives, rx, 1, 0x0000)
    _run(drives, rx, 1, sm.CW_FAULT_RESET)
    assert _states(drives)[5] == State.SWITCH_ON_DISABLED
    assert drives.tx["error_code"][5] == 0 and drives.error_register[5] == 0


def test_following_error_detected_without_injection(drives: EmulatedDrives) -> None:
    rx = drives.rx.copy()
    _run(drives, rx, 1)
    _enable(drives, rx, Mode.CSP)
    window = int(drives.following_window[2])
    rx["target_position"][2] += 20 * window  # a jump the axis cannot follow in 10 ms
    for _ in range(30):
        drives.step(rx)
    assert _states(drives)[2] in (State.FAULT_REACTION_ACTIVE, State.FAULT)
    assert drives.tx["error_code"][2] == 0x8611
    assert _states(drives)[0] == State.OPERATION_ENABLED


def test_watchdog_faults_only_powered_drives(drives: EmulatedDrives) -> None:
    rx = drives.rx.copy()
    _run(drives, rx, 1)
    _run(drives, rx, 2, sm.CW_SHUTDOWN)  # ready to switch on: no power stage
    for _ in range(drives.watchdog_cycles + 1):
        drives.step(None)
    assert _states(drives) == [State.READY_TO_SWITCH_ON] * 6
    _enable(drives, rx, Mode.CSP)
    for _ in range(drives.watchdog_cycles):
        drives.step(None)
    assert _states(drives) == [State.OPERATION_ENABLED] * 6  # within the watchdog
    drives.step(None)
    assert all(drives.fault_code == 0x8130)


def test_quick_stop_option_6_holds_and_allows_transition_16(drives: EmulatedDrives) -> None:
    rx = drives.rx.copy()
    _run(drives, rx, 1)
    drives.ods[0].write(0x605A, 0, struct.pack("<h", 6))
    _enable(drives, rx, Mode.CSP)
    _run(drives, rx, 200, sm.CW_QUICK_STOP)
    st = _states(drives)
    assert st[0] == State.QUICK_STOP_ACTIVE  # option 6: stay after the ramp
    assert st[1] == State.SWITCH_ON_DISABLED  # default option 2: disable after the ramp
    _run(drives, rx, 1, sm.CW_ENABLE_OPERATION)
    assert _states(drives)[0] == State.OPERATION_ENABLED  # transition 16
    assert _states(drives)[1] == State.SWITCH_ON_DISABLED  # illegal there: unchanged


def test_unsupported_mode_is_not_displayed(drives: EmulatedDrives) -> None:
    rx = drives.rx.copy()
    rx["mode"] = Mode.CSV
    drives.step(rx)
    assert all(drives.tx["mode_display"] == Mode.CSV)
    rx["mode"] = 1  # profile position: not emulated (homing, 6, is: test_homing.py)
    drives.step(rx)
    assert all(drives.tx["mode_display"] == Mode.CSV)


def test_encoder_fault_freezes_position_and_sto_blocks_power(drives: EmulatedDrives) -> None:
    rx = drives.rx.copy()
    _run(drives, rx, 1)
    _enable(drives, rx, Mode.CST)
    drives.inject_fault(4, "encoder")
    rx["target_torque"][4] = 500  # would move the joint if the drive still had power
    frozen = int(drives.tx["position"][4])
    _run(drives, rx, 20)
    assert _states(drives)[4] == State.FAULT and drives.tx["error_code"][4] == 0x7305
    assert drives.tx["position"][4] == frozen
    drives.set_safe_torque_off(0, True)
    drives.step(rx)
    assert _states(drives)[0] == State.SWITCH_ON_DISABLED
    assert drives.tx["digital_inputs"][0] == 1 << 16
    _run(drives, rx, 3, sm.CW_SHUTDOWN)
    assert _states(drives)[0] == State.SWITCH_ON_DISABLED  # transition 2 refused


def test_reset_power_cycles_drives_and_plant(drives: EmulatedDrives) -> None:
    rx = drives.rx.copy()
    _run(drives, rx, 1)
    _enable(drives, rx, Mode.CSP)
    q0 = np.full(6, 0.2)
    drives.reset(q0)
    assert _states(drives) == [State.NOT_READY_TO_SWITCH_ON] * 6
    assert np.allclose(drives.plant.q, q0)
    _run(drives, rx, 100, 0)
    assert np.max(np.abs(drives.plant.q - q0)) < 2e-3  # brake holds at the new pose


def test_steady_cycle_allocates_no_arrays(
    drives: EmulatedDrives, monkeypatch: pytest.MonkeyPatch
) -> None:
    import tracemalloc

    rx = drives.rx.copy()
    _run(drives, rx, 1)
    _enable(drives, rx, Mode.CSP)
    monkeypatch.setattr(drives.plant, "step", lambda tau: None)  # measure the drives only
    _run(drives, rx, 5)
    tracemalloc.start()
    _run(drives, rx, 50)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert peak < 3000  # bytes over 50 cycles: scalars only, no per-cycle arrays
