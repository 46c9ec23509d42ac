"""The emulated drive's real holding brake: delays, gravity preload, a worn brake."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.cia402 import state_machine as sm
from drivers.cia402.state_machine import Mode, State
from drivers.sim.drive import EmulatedDrives, LoopTuning

AXIS = 1  # the shoulder: carries the arm's weight


@pytest.fixture
def d(cfg) -> EmulatedDrives:
    """The ER3A's drives with a 60 rad/s velocity loop (the emulator's default 150 rad/s is
    stiffer than most arm servo tunings: there the sag without preload is 0.43 mrad)."""
    from hofto_hw.runtime.build import build_sim_bus

    plant = build_sim_bus(cfg, external=False).drives.plant
    inertia = np.diag(plant.data.mass_matrix(plant.q)).copy()
    limits = np.array([x.torque_limit for x in cfg.bus.drives])
    return EmulatedDrives(
        plant, cfg.bus.drives, tuning=LoopTuning.from_inertia(inertia, limits, 60.0)
    )


def _gravity(d: EmulatedDrives) -> np.ndarray:
    p = d.plant
    return p.true_model.create_data().gravity(p.q_meas).copy()


def _brake(d: EmulatedDrives, holding: float | None = None) -> float:
    g = abs(float(_gravity(d)[AXIS]))
    assert g > 5.0  # a gravity-loaded axis
    d.configure_brake(AXIS, release_delay=0.1, engage_delay=0.05, holding_torque=holding or 3 * g)
    return g


def _enable(d: EmulatedDrives, preload: bool, seconds: float = 1.0) -> float:
    """Enable in CSP holding the read position (with or without the gravity torque as
    0x60B2 before the brake opens); the largest joint motion [rad] over ``seconds``."""
    rx = d.rx.copy()
    rx["mode"] = Mode.CSP
    d.step(rx)
    q0 = float(d.plant.q_meas[AXIS])
    rx["target_position"] = d.tx["position"]
    if preload:
        d.scaling.torque_to_raw(_gravity(d), rx["torque_offset"])
    for cw in (sm.CW_SHUTDOWN, sm.CW_SWITCH_ON, sm.CW_ENABLE_OPERATION):
        rx["controlword"] = cw
        for _ in range(2):
            d.step(rx)
    assert sm.decode_state(int(d.tx["statusword"][AXIS])) == State.OPERATION_ENABLED
    assert d.brake_engaged[AXIS]  # still closed: the release delay runs
    worst = 0.0
    for _ in range(round(seconds / d.dt)):
        d.step(rx)
        worst = max(worst, abs(float(d.plant.q_meas[AXIS]) - q0))
    assert not d.brake_engaged[AXIS]
    return worst


def test_enable_with_the_gravity_preload_moves_less_than_half_a_mrad(d: EmulatedDrives) -> None:
    _brake(d)
    assert _enable(d, preload=True) < 0.5e-3  # measured 0.13 mrad


def test_enable_without_the_preload_sags(d: EmulatedDrives) -> None:
    _brake(d)
    assert _enable(d, preload=False) > 2e-3  # measured 3.3 mrad: the integrator winds up late


def test_brake_opens_after_its_release_delay_and_closes_after_power_off(d: EmulatedDrives) -> None:
    _brake(d)
    rx = d.rx.copy()
    rx["mode"] = Mode.CSP
    d.step(rx)
    rx["target_position"] = d.tx["position"]
    d.scaling.torque_to_raw(_gravity(d), rx["torque_offset"])
    for cw in (sm.CW_SHUTDOWN, sm.CW_SWITCH_ON, sm.CW_ENABLE_OPERATION):
        rx["controlword"] = cw
        for _ in range(2):
            d.step(rx)
    cycles = 0
    while d.brake_engaged[AXIS]:
        d.step(rx)
        cycles += 1
    assert cycles * d.dt == pytest.approx(0.1, abs=3 * d.dt)
    rx["controlword"] = sm.CW_DISABLE_VOLTAGE  # category 0: power off at once
    d.step(rx)
    assert not d.brake_engaged[AXIS]  # the engage delay runs: the arm is free meanwhile
    for _ in range(round(0.05 / d.dt) + 1):
        d.step(rx)
    assert d.brake_engaged[AXIS]


def test_a_worn_brake_slips_under_the_arms_weight(d: EmulatedDrives) -> None:
    g = _brake(d)
    rx = d.rx.copy()

    def drift() -> float:  # joint motion over 0.5 s after 0.3 s of settling, power off
        for _ in range(round(0.3 / d.dt)):
            d.step(rx)
        q = float(d.plant.q_meas[AXIS])
        for _ in range(round(0.5 / d.dt)):
            d.step(rx)
        return abs(float(d.plant.q_meas[AXIS]) - q)

    assert drift() < 1e-3  # a good brake holds (what moves is the other axes settling)
    d.configure_brake(AXIS, 0.1, 0.05, holding_torque=0.5 * g)  # worn: half the weight
    assert drift() > 0.01  # slips
