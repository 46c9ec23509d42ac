"""Drives without a cyclic synchronous mode on the CANopen master: the shipped Technosoft iPOS
profile (interpolated position, mode 7) and Faulhaber MCBL 300x profile (profile velocity
streamed, mode 3) on one virtual bus with the emulator impersonating them. The loop commands
CSP; the wire carries 0x60C1:01 + controlword bit 4, or a velocity every SYNC."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
import yaml
from support.canopen import CONFIG, unique_channel
from support.profiles import write_mixed_config

from drivers.cia402.csp_adapter import CW_ENABLE_IP, SW_IP_ACTIVE
from drivers.cia402.drive_group import DriveGroup, DriveTimeoutError
from drivers.cia402.state_machine import CW_ENABLE_OPERATION, Mode, State
from drivers.transport import STATUS_OK

ROOT = Path(__file__).resolve().parents[3]
TECHNOSOFT = yaml.safe_load((ROOT / "configs/drives/technosoft_ipos.yaml").read_text())
SHIPPED_FAULHABER = yaml.safe_load((ROOT / "configs/drives/faulhaber_mcbl300x.yaml").read_text())
# its EDS does not say the velocity unit (units.velocity unknown: a real bus refuses it); the
# emulator runs what the profile states, so the tests state it: counts/s, or rpm below
FAULHABER = copy.deepcopy(SHIPPED_FAULHABER)
FAULHABER["units"].update(velocity="counts/s", acceleration="counts/s^2")
FAULHABER_RPM = copy.deepcopy(SHIPPED_FAULHABER)
FAULHABER_RPM["units"].update(velocity="rpm", acceleration="rpm/s")
IP = np.array([True, False] * 3)
PV = ~IP


@pytest.fixture()
def bus(tmp_path: Path, request):
    import can

    from drivers.canopen.master import CANopenTransport
    from drivers.cia402.profiles import profiles_for
    from drivers.sim.canopen_node import CanopenDrives
    from hofto_hw.config.loader import load_config
    from hofto_hw.runtime.build import build_emulated_drives

    faulhaber = getattr(request, "param", FAULHABER)
    cfg = load_config(write_mixed_config(tmp_path, [TECHNOSOFT, faulhaber] * 3, base=CONFIG))
    channel = unique_channel()
    can_bus = can.Bus(interface="virtual", channel=channel)
    emu = CanopenDrives(build_emulated_drives(cfg, external=False), can_bus).start()
    t = CANopenTransport(
        channel,
        cfg.bus.drives,
        cfg.cycle_time,
        list(cfg.robot.joints),
        can_interface="virtual",
        tpdo_deadline=0.05,
        heartbeat_timeout=0.5,
        sdo_timeout=2.0,
        profiles=profiles_for(cfg.bus.drives, "canopen"),
    )
    try:
        yield cfg, t, emu
    finally:
        t.close()
        emu.stop()
        can_bus.shutdown()


def _cycles(g: DriveGroup, k: int, target: np.ndarray | None = None) -> int:
    """``k`` cycles commanding ``target``; returns how many brought fresh data (a loaded
    machine may miss a TPDO deadline now and then: the emulator steps once per SYNC anyway)."""
    fresh = 0
    for _ in range(k):
        if target is not None:
            g.command_position(target)
        fresh += g.cycle() == STATUS_OK
        g.transport.wait_next_cycle()
    return fresh


def test_loop_in_csp_drives_run_ip_and_pv(bus) -> None:
    cfg, t, emu = bus
    t.open()
    drives = emu.drives
    # start-up: the interpolation period is the loop's (200 Hz: 5 x 1e-3 s), linear sub-mode
    assert cfg.cycle_time == pytest.approx(0.005)
    assert drives.ip_period[IP].tolist() == [5] * 3
    assert drives.ip_exponent[IP].tolist() == [-3] * 3
    assert t.startup_written == 3 * 3
    g = DriveGroup.from_config(t, cfg.bus)
    g.set_mode(Mode.CSP)  # the loop asks CSP; each drive gets its own mode
    assert drives.mode_display.tolist() == [7, 3] * 3
    accel = [g.scaling.acceleration_to_raw(i, d.quick_stop_deceleration)
             for i, d in enumerate(cfg.bus.drives)]  # fmt: skip
    assert drives.profile_accel[PV].tolist() == np.array(accel)[PV].tolist()
    assert drives.profile_decel[PV].tolist() == np.array(accel)[PV].tolist()
    g.enable()
    assert g.all_in(State.OPERATION_ENABLED)
    # ip acknowledged (statusword bit 12) after controlword bit 4, which the loop never wrote
    assert ((g.transport.tx["statusword"] & SW_IP_ACTIVE) != 0)[IP].all()
    assert (drives.rx["controlword"][IP] & CW_ENABLE_IP).all()
    assert not (drives.rx["controlword"][PV] & CW_ENABLE_IP).any()
    assert (t.rx["controlword"] == CW_ENABLE_OPERATION).all()
    # a CSP ramp of 0.05 rad: ip drives take it in 0x60C1:01, pv drives as velocities
    q0 = g.q.copy()
    ramp = 80
    streamed = np.zeros(6)
    for k in range(1, ramp + 1):
        _cycles(g, 1, q0 + 0.05 * k / ramp)
        streamed = np.maximum(streamed, np.abs(drives.rx["target_velocity"]))
    # the emulated arm at 200 Hz swings about the target for ~2 s as it does with CSP drives
    # (±5 mrad, the same with the zeroerr_erob CSP profile): 10 % as the drive check
    assert _cycles(g, 400, q0 + 0.05) > 200
    np.testing.assert_allclose(g.q - q0, 0.05, atol=5e-3)
    assert (streamed[PV] > 0).all()  # 0x60FF carried the motion
    assert (t.rx["target_velocity"] == 0).all()  # the loop's own record stayed CSP
    np.testing.assert_array_equal(drives.rx["target_position"][IP], t.rx["target_position"][IP])
    assert (g.transport.tx["statusword"][PV] & 0x1000).all()  # pv at rest: speed zero
    # a quick stop: bit 4 falls with the command, the drives ramp to rest and switch off
    g.quick_stop()
    assert not (drives.rx["controlword"] & CW_ENABLE_IP).any()
    assert all(s in (State.SWITCH_ON_DISABLED, State.QUICK_STOP_ACTIVE) for s in g.states)


def test_ip_drive_without_an_interpolation_period_never_acknowledges(bus) -> None:
    cfg, t, emu = bus
    t.open()
    t.write_value(0, 0x60C2, 1, "u8", 0)  # as if the start-up write had not happened
    g = DriveGroup.from_config(t, cfg.bus)
    g.set_mode(Mode.CSP)
    with pytest.raises(DriveTimeoutError) as err:
        g.enable()
    msg = str(err.value)
    assert msg.startswith("axis 0 (joint_1): interpolated position mode not active")
    assert "statusword bit 12" in msg and "0x60C2" in msg and "\n" not in msg
    assert emu.drives.state[0] == State.OPERATION_ENABLED  # enabled, holding, not following


def test_emulated_drives_take_only_their_profiles_modes(bus) -> None:
    """The emulated Faulhaber has no ip (its 0x6060 stops at 6), the Technosoft no CSP: a
    group that asks them for those modes times out naming the axis and the mode shown."""
    cfg, t, emu = bus
    t.open()
    g = DriveGroup.from_config(t, cfg.bus)
    with pytest.raises(DriveTimeoutError) as err:
        g.set_mode(Mode.INTERPOLATED_POSITION)
    assert "axis 1 (joint_2)" in str(err.value) and "selecting 7" in str(err.value)
    assert emu.drives.mode_display.tolist() == [7, 0] * 3
    with pytest.raises(DriveTimeoutError):
        g.set_mode(Mode.CSV)  # neither drive has a cyclic synchronous mode


def test_configure_leaves_out_the_settings_the_drives_lack(bus) -> None:
    """Neither drive has 0x6072 max torque nor 0x6075/0x6076 motor ratings; the Faulhaber has
    no following-error window/timeout either. The emulator impersonating them aborts an SDO to
    those (0x06020000, as the real drive), so configure writes only what each drive has and
    says once per axis what it left out."""
    from drivers.errors import SdoAbortError

    cfg, t, emu = bus
    t.open()
    with pytest.raises(SdoAbortError) as err:
        t.write_value(0, 0x6072, 0, "u16", 1000)
    assert err.value.code == 0x06020000
    t.read_value(0, 0x6065, 0, "u32")  # the Technosoft has the following-error window
    with pytest.raises(SdoAbortError) as err:
        t.read_value(1, 0x6065, 0, "u32")
    assert err.value.code == 0x06020000
    g = DriveGroup.from_config(t, cfg.bus)
    g.configure(cfg.bus.drives)
    notes = g.settings_notes
    assert len(notes) == 6 and all("\n" not in n for n in notes)
    assert notes[0].startswith("axis 0 (joint_1, technosoft_ipos): no 0x6072 max_torque: ")
    assert notes[1].startswith("axis 1 (joint_2, faulhaber_mcbl300x): no 0x6072 max_torque: ")
    assert "the stack's joint torque limit (safety.limits) applies" in notes[1]
    assert "0x6065" not in notes[0] and "0x6065 following_error_window" in notes[1]
    assert "0x6066" in notes[1] and "0x6076 rated_torque" in notes[0]
    # what the drives have was written: the quick-stop ramp everywhere, the window on iPOS
    decel = [g.scaling.acceleration_to_raw(i, d.quick_stop_deceleration)
             for i, d in enumerate(cfg.bus.drives)]  # fmt: skip
    assert [t.read_value(i, 0x6085, 0, "u32") for i in range(6)] == decel
    window = g.scaling.angle_to_counts(0, cfg.bus.drives[0].following_error_window)
    assert t.read_value(0, 0x6065, 0, "u32") == window


def test_a_profile_without_the_velocity_unit_is_refused_before_the_bus_opens(tmp_path) -> None:
    """The shipped Faulhaber profile says units.velocity unknown (its EDS has no velocity
    factor objects): the master refuses it in one line naming the joint, before any frame."""
    from drivers.canopen.master import CANopenTransport
    from drivers.cia402.profiles import profiles_for
    from hofto_hw.config.loader import load_config
    from hofto_hw.errors import ConfigError

    cfg = load_config(
        write_mixed_config(tmp_path, [TECHNOSOFT, SHIPPED_FAULHABER] * 3, base=CONFIG)
    )
    with pytest.raises(ConfigError) as err:
        CANopenTransport(
            unique_channel(),
            cfg.bus.drives,
            cfg.cycle_time,
            list(cfg.robot.joints),
            can_interface="virtual",
            profiles=profiles_for(cfg.bus.drives, "canopen"),
        )
    assert str(err.value) == (
        "joint_2 (faulhaber_mcbl300x): the drive's velocity unit is not stated in its file; "
        "set units.velocity in the profile (counts/s or rpm) after checking the drive's manual"
    )


@pytest.mark.parametrize("bus", [FAULHABER_RPM], indirect=True, ids=["rpm"])
def test_pv_drive_in_rpm_moves_and_takes_its_ramps_in_rpm_per_s(bus) -> None:
    """A Faulhaber profile stating rpm and rpm/s: the master writes 0x6083/0x6084/0x6085 in
    rpm/s, streams 0x60FF in rpm and reads 0x606C back into counts/s; the emulated drive runs
    in the same unit and the arm moves 0.05 rad with no fault."""
    cfg, t, emu = bus
    t.open()
    drives = emu.drives
    per_rpm = cfg.bus.drives[1].counts_per_rev / 60.0  # counts/s per rpm (counts per motor rev)
    np.testing.assert_array_equal(drives.velocity_unit[PV], per_rpm)
    np.testing.assert_array_equal(drives.velocity_unit[IP], 1.0)
    g = DriveGroup.from_config(t, cfg.bus)
    g.configure(cfg.bus.drives)
    g.set_mode(Mode.CSP)
    counts = np.array([g.scaling.acceleration_to_raw(i, d.quick_stop_deceleration)
                       for i, d in enumerate(cfg.bus.drives)])  # fmt: skip
    rpm_s = np.rint(counts / per_rpm)
    assert (rpm_s[PV] < counts[PV] / 40).all()  # not the counts/s² value
    assert drives.profile_accel[PV].tolist() == rpm_s[PV].tolist()  # 0x6083 [rpm/s]
    assert drives.profile_decel[PV].tolist() == rpm_s[PV].tolist()  # 0x6084 [rpm/s]
    assert [t.read_value(i, 0x6083, 0, "u32") for i in (1, 3, 5)] == rpm_s[PV].tolist()
    assert [t.read_value(i, 0x6085, 0, "u32") for i in (1, 3, 5)] == rpm_s[PV].tolist()
    assert [t.read_value(i, 0x6085, 0, "u32") for i in (0, 2, 4)] == counts[IP].tolist()
    g.enable()
    assert g.all_in(State.OPERATION_ENABLED)
    q0 = g.q.copy()
    ramp = 80
    streamed, reported, seen, qd = np.zeros(6), np.zeros(6), np.zeros(6), np.zeros(6)
    for k in range(1, ramp + 1):
        _cycles(g, 1, q0 + 0.05 * k / ramp)
        streamed = np.maximum(streamed, np.abs(drives.rx["target_velocity"]))
        reported = np.maximum(reported, np.abs(drives.tx["velocity"]))
        seen = np.maximum(seen, np.abs(t.tx["velocity"]))
        qd = np.maximum(qd, np.abs(g.qd))
    assert _cycles(g, 400, q0 + 0.05) > 200
    np.testing.assert_allclose(g.q - q0, 0.05, atol=5e-3)
    assert not g.any_fault() and (drives.fault_code == 0).all()
    assert (streamed[PV] > 0).all()
    # 0x606C in rpm on the wire, counts/s in the master's canonical record
    np.testing.assert_allclose(seen[PV], reported[PV] * per_rpm, rtol=0.05)
    # the velocity the loop reads is in rad/s as with a counts/s drive: the ramp is 0.05 rad
    # in 80 cycles of 5 ms (0.125 rad/s); read as rpm it would be 50 x too small
    assert ((qd[PV] > 0.05) & (qd[PV] < 0.5)).all(), qd
