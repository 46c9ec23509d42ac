"""The drive layer over the in-process SimBus: enable, modes, moves, stops, faults, timeouts."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from drivers.cia402.drive_group import DriveFaultError, DriveGroup, DriveTimeoutError
from drivers.cia402.state_machine import Mode, State
from drivers.sim.drive import FAULTS
from drivers.sim.simbus import SimBus
from drivers.transport import STATUS_NO_RESPONSE
from hofto_hw.config.loader import load_config
from hofto_hw.config.models import SystemConfig
from hofto_hw.errors import ConfigError
from hofto_hw.runtime.build import build_sim_bus

CONFIG = Path(__file__).resolve().parents[3] / "configs" / "er3a.yaml"


@pytest.fixture
def bus(bus: SimBus) -> SimBus:
    """The shared quiet SimBus (tests/drivers/conftest.py), opened."""
    bus.open()
    return bus


@pytest.fixture
def group(bus: SimBus, cfg: SystemConfig) -> DriveGroup:
    g = DriveGroup.from_config(bus, cfg.bus)
    g.configure(cfg.bus.drives)
    return g


def _enabled(group: DriveGroup, mode: Mode = Mode.CSP) -> DriveGroup:
    group.set_mode(mode)
    group.enable()
    return group


def test_enable_all_holds_position(group: DriveGroup, bus: SimBus) -> None:
    q0 = bus.plant.q.copy()
    _enabled(group)
    assert group.all_in(State.OPERATION_ENABLED)
    assert bus.plant.t < 0.05  # a handful of cycles, not the timeout
    for _ in range(200):
        group.cycle()
    assert np.max(np.abs(bus.plant.q - q0)) < 2e-3
    assert np.allclose(group.q, bus.plant.q, atol=2e-6)  # SI decode of encoder counts


def test_configure_writes_limits_and_checks_identity(
    group: DriveGroup, bus: SimBus, cfg: SystemConfig
) -> None:
    d = cfg.bus.drives[3]
    expected = round(d.torque_limit / (d.rated_torque * 1e-6 * d.gear_ratio))
    assert bus.read_value(3, 0x6072, 0, "u16") == expected
    wrong = [x.model_copy(deep=True) for x in cfg.bus.drives]
    wrong[4].identity.product_code = 0x1234
    with pytest.raises(ConfigError, match=r"bus\.drives\[4\]\.identity: axis 4 \(joint_5\)"):
        group.configure(wrong)
    wrong = [x.model_copy(deep=True) for x in cfg.bus.drives]
    wrong[1].rated_torque = 999.0
    with pytest.raises(ConfigError, match=r"bus\.drives\[1\]\.rated_torque: .*0x6076"):
        group.configure(wrong)


def test_csp_move_on_every_joint_is_followed(group: DriveGroup, bus: SimBus) -> None:
    _enabled(group)
    q0 = group.q.copy()
    amp = np.array([0.3, -0.2, 0.25, -0.4, 0.35, 0.5])
    T, worst = 0.6, 0.0
    for k in range(900):
        s = min(k * 1e-3 / T, 1.0)
        qc = q0 + amp * (s - np.sin(2 * np.pi * s) / (2 * np.pi))  # smooth 0 -> 1
        group.command_position(qc)
        assert group.cycle() == 0
        worst = max(worst, float(np.max(np.abs(qc - bus.plant.q))))
    assert worst < 0.02
    assert np.all(np.abs(bus.plant.q - (q0 + amp)) < 2e-3)
    assert np.all(np.sign(bus.plant.q - q0) == np.sign(amp))


def test_cst_torque_reaches_the_plant(group: DriveGroup, bus: SimBus) -> None:
    plant = bus.plant
    _enabled(group)
    model = plant.true_model
    tau = model.create_data().gravity(plant.q).copy()
    tau[0] += 8.0
    tau[3] -= 4.0  # beyond the wrist's 1.8 N·m breakaway friction
    group.command_torque(tau)
    group.set_mode(Mode.CST)
    for _ in range(40):
        group.cycle()
    raw_step = np.abs(group.scaling.nm_per_permille)
    assert np.all(np.abs(plant.tau_applied - tau) <= 0.5 * raw_step + 1e-9)
    expected = model.create_data().forward_dynamics(
        plant.q, plant.qd, plant.tau_applied, plant.tau_ext
    )
    assert np.allclose(plant.qdd, expected, rtol=0.05, atol=0.05)
    assert expected[0] > 1.0 and expected[3] < -1.0  # the offsets really accelerate
    assert np.allclose(group.tau, plant.tau_meas, atol=raw_step.max())  # reported back


@pytest.mark.parametrize("mode", [Mode.CSP, Mode.CSV, Mode.CST])
def test_enable_is_bumpless_under_gravity(mode: Mode, group: DriveGroup, bus: SimBus) -> None:
    """Enabling must not drop the arm (defect 2): CSP holds the measured position, CSV
    commands zero velocity, CST keeps the caller's gravity torque from the first enabled
    cycle. Before the fix, CST enable wrote zero torque and joint 2 sagged 0.026 rad."""
    plant = bus.plant
    tau_g = plant.true_model.create_data().gravity(plant.q).copy()  # holds the true arm
    assert abs(tau_g[1]) > 10.0  # joint 2 really carries the arm
    q0 = plant.q.copy()
    group.set_mode(mode)
    if mode == Mode.CST:
        group.command_torque(tau_g)
    group.enable()
    assert group.all_in(State.OPERATION_ENABLED)
    if mode == Mode.CST:
        raw_step = np.abs(group.scaling.nm_per_permille)
        assert np.all(np.abs(plant.tau_applied - tau_g) <= 0.5 * raw_step + 1e-9)
    for _ in range(100):  # 0.1 s of holding
        assert group.cycle() == 0
    assert np.max(np.abs(plant.q - q0)) < 2e-3


def test_quick_stop_ramps_velocity_down_then_disables(
    group: DriveGroup, bus: SimBus, cfg: SystemConfig
) -> None:
    _enabled(group, Mode.CSV)
    v0 = 0.5
    for _ in range(300):
        group.command_velocity(np.full(6, v0))
        group.cycle()
    assert np.allclose(group.qd, v0, atol=0.02)
    group.command_quick_stop()
    speeds, states = [], []
    for _ in range(400):
        group.cycle()
        speeds.append(np.abs(group.qd.copy()))
        states.append(group.states.copy())
    speeds, states = np.array(speeds), np.array(states)
    decel = np.array([d.quick_stop_deceleration for d in cfg.bus.drives])
    ramp_cycles = v0 / decel / 1e-3
    for j in range(6):
        qs = np.flatnonzero(states[:, j] == State.QUICK_STOP_ACTIVE)
        assert qs[0] == 0  # quick stop active from the first cycle
        # Speed falls along the ramp: halfway through, about half the speed is left.
        half = int(ramp_cycles[j] / 2)
        assert speeds[half, j] == pytest.approx(v0 / 2, abs=0.1)
        # Disabled once stopped, within 50 % of the nominal ramp time (+ settling).
        off = np.flatnonzero(states[:, j] == State.SWITCH_ON_DISABLED)
        assert off.size and ramp_cycles[j] * 0.8 <= off[0] <= ramp_cycles[j] * 1.5 + 30
        assert speeds[off[0], j] < 0.02
    assert group.all_in(State.SWITCH_ON_DISABLED)


def test_blocking_quick_stop_and_disable(group: DriveGroup, bus: SimBus) -> None:
    _enabled(group, Mode.CSV)
    for _ in range(100):
        group.command_velocity(np.full(6, 0.3))
        group.cycle()
    group.quick_stop()
    assert group.all_in(State.SWITCH_ON_DISABLED)
    _enabled(group)
    group.disable()
    assert group.all_in(State.SWITCH_ON_DISABLED)
    q = bus.plant.q.copy()
    for _ in range(300):
        group.cycle()
    assert np.max(np.abs(bus.plant.q - q)) < 2e-3  # brakes hold the disabled arm


@pytest.mark.parametrize("kind", sorted(FAULTS))
def test_each_injected_fault_surfaces_decoded(kind: str, group: DriveGroup, bus: SimBus) -> None:
    from drivers.cia402.codes import describe_error_code

    code = FAULTS[kind][0]
    _enabled(group)
    bus.inject_fault(3, kind)
    for _ in range(300):
        group.cycle()
        if group.states[3] == State.FAULT:
            break
    assert group.states[3] == State.FAULT
    assert group.any_fault()
    assert bus.read_value(3, 0x603F, 0, "u16") == code
    msgs = group.fault_messages()
    assert msgs == [f"axis 3 (joint_4): {msgs[0].split(': ')[1]}: {describe_error_code(code)}"]
    assert "Fault (statusword" in msgs[0]
    with pytest.raises(DriveFaultError, match=r"axis 3 \(joint_4\).*" + f"0x{code:04X}") as e:
        group.enable()
    assert e.value.error_code == code and e.value.axis == 3
    group.fault_reset()
    assert not group.any_fault()
    group.enable()
    assert group.all_in(State.OPERATION_ENABLED)


def test_lost_frames_give_status_then_comm_loss_fault(group: DriveGroup, bus: SimBus) -> None:
    _enabled(group)
    bus.drop_cycles(1)
    assert group.cycle() != 0
    assert group.cycle() == 0 and not group.any_fault()  # one lost frame is tolerated
    bus.drop_cycles(10)
    statuses = [group.cycle() for _ in range(12)]
    assert statuses[:10] == [2] * 10 and statuses[10:] == [0, 0]
    for _ in range(200):
        group.cycle()
    assert all(group.states == State.FAULT)
    assert all("0x8130 communication lost" in m for m in group.fault_messages())


def test_stale_data_after_a_lost_frame_is_flagged(group: DriveGroup, bus: SimBus) -> None:
    """cycle() returns the status and sets `fresh` (defect 5): the TxPDO of a lost frame is
    the previous cycle's, and the caller must be able to tell."""
    _enabled(group, Mode.CSV)
    for _ in range(50):
        group.command_velocity(np.full(6, 0.2))
        assert group.cycle() == 0
        assert group.fresh and group.stale_cycles == 0
    q_before = group.q.copy()
    bus.drop_cycles(2)
    assert group.cycle() == STATUS_NO_RESPONSE
    assert not group.fresh and group.stale_cycles == 1
    np.testing.assert_array_equal(group.q, q_before)  # stale: the same values again
    assert not np.allclose(bus.plant.q_meas, q_before)  # ... while the arm moved on
    assert group.cycle() == STATUS_NO_RESPONSE and group.stale_cycles == 2
    assert group.cycle() == 0
    assert group.fresh and group.stale_cycles == 0
    np.testing.assert_allclose(group.q, bus.plant.q_meas, atol=1e-5)


def test_persistent_fault_refuses_reset_with_the_decoded_cause(
    group: DriveGroup, bus: SimBus
) -> None:
    _enabled(group)
    bus.inject_fault(1, "over_voltage", persistent=True)
    for _ in range(3):
        group.cycle()
    with pytest.raises(DriveFaultError, match=r"cause still present: axis 1 \(joint_2\).*0x3210"):
        group.fault_reset()
    bus.drives.clear_fault(1)
    group.fault_reset()
    assert group.states[1] == State.SWITCH_ON_DISABLED


def test_enable_timeout_names_axis_state_and_statusword(group: DriveGroup, bus: SimBus) -> None:
    group.set_mode(Mode.CSP)
    real_cycle, calls = group.cycle, [0]

    def cycle() -> int:  # STO asserted just after enable()'s STO check: a stuck transition
        calls[0] += 1
        if calls[0] == 2:
            bus.drives.set_safe_torque_off(2, True)
        return real_cycle()

    def unseen(out, by_state):  # a drive whose STO signal the master does not see
        out.fill(False)
        return out

    group.cycle = cycle  # type: ignore[method-assign]
    group.sto_in_image = unseen  # type: ignore[method-assign]
    group.sto_axes = list  # type: ignore[method-assign]
    t0 = bus.plant.t
    with pytest.raises(DriveTimeoutError) as e:
        group.enable()
    msg = str(e.value)
    assert "axis 2 (joint_3)" in msg and "Switch on disabled" in msg and "0x0240" in msg
    assert msg.endswith("safe torque off active? (the drive stays in switch on disabled)")
    assert e.value.axis == 2 and e.value.state == State.SWITCH_ON_DISABLED
    assert 0.5 <= bus.plant.t - t0 < 0.6  # the configured 0.5 s, in bus time


def test_mode_display_check_times_out_on_unsupported_mode(group: DriveGroup) -> None:
    group.set_mode(Mode.CSP)
    with pytest.raises(
        DriveTimeoutError,
        match=r"axis 0 \(joint_1\): mode of operation display"
        r" 0x6061 shows 8 \(CSP\).*1 \(PROFILE_POSITION\)",
    ):
        group.set_mode(Mode.PROFILE_POSITION)


def test_read_and_commands_do_not_allocate(group: DriveGroup) -> None:
    import tracemalloc

    _enabled(group)
    q = group.q.copy()
    group.read()
    group.command_position(q)
    tracemalloc.start()
    for _ in range(50):
        group.read()
        group.command_position(q, q)
        group.command_torque(q)
        group.any_fault()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert peak < 2000  # bytes: no arrays created per call


def test_ur10e_bus_at_500_hz_enables_and_follows() -> None:
    cfg = load_config(CONFIG.parent / "ur10e.yaml")
    bus = build_sim_bus(cfg, external=False)
    group = DriveGroup.from_config(bus, cfg.bus)
    with bus:
        group.configure(cfg.bus.drives)
        _enabled(group)
        q0 = group.q.copy()
        for k in range(600):  # 1.2 s at 2 ms: 0.5 s ramp, then settling
            group.command_position(q0 + 0.1 * min(1.0, k / 250))
            group.cycle()
        assert np.all(np.abs(bus.plant.q - (q0 + 0.1)) < 3e-3)
        assert group.all_in(State.OPERATION_ENABLED)
