"""The pysoem master runs six different drive profiles on one emulated bus (root): each
emulated slave impersonates its profile (identity, fixed/configurable PDOs, padding,
absent objects, start-up mode, DC requirement); the master configures each drive as its
profile says, reads the layout back and runs the CiA-402 group over the mixed image."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
from support.profiles import ELMO, INOVANCE, MIXED, NANOTEC, profile, write_mixed_config
from support.rootnet import emulator, sim_ethercat_args, veth_pair

from drivers.cia402.drive_group import DriveGroup
from drivers.cia402.state_machine import Mode, State
from drivers.ethercat.errors import EtherCATError, RegisterMismatchError, StateChangeError
from drivers.ethercat.master import EtherCATTransport
from drivers.transport import STATUS_OK, SdoAbortError
from hofto_hw.config.loader import load_config
from hofto_hw.errors import ConfigError

pytestmark = pytest.mark.root


@pytest.fixture()
def mixed_bus(tmp_path: Path):
    config = write_mixed_config(tmp_path)
    cfg = load_config(config)
    with (
        veth_pair("pm", "ps") as (master, slave),
        emulator(sim_ethercat_args(slave, config), tmp_path, timeout=30.0) as emu,
    ):
        yield master, cfg, emu


def _transport(master: str, cfg, profiles=None, **kw) -> EtherCATTransport:
    from drivers.cia402.profiles import profiles_for

    return EtherCATTransport(
        master,
        cfg.bus.drives,
        cfg.cycle_time,
        list(cfg.robot.joints),
        receive_timeout=0.02,
        pdo_watchdog=2.0,
        profiles=profiles if profiles is not None else profiles_for(cfg.bus.drives, "ethercat"),
        **kw,
    )


def test_six_profiles_run_on_one_bus_with_the_layouts_the_drives_report(mixed_bus, capfd) -> None:
    master, cfg, emu = mixed_bus
    t = _transport(master, cfg)
    try:
        t.open()
        lay = t.wire.layouts
        assert [x.rx_pdos for x in lay] == [
            (0x1605,),
            (0x1600,),
            (0x1600, 0x1601),
            (0x1600,),
            (0x1600, 0x1601, 0x1602),
            (0x1600,),
        ]
        assert [x.tx_pdos for x in lay][4] == (0x1A00, 0x1A01, 0x1A02, 0x1A03)
        assert [len(s.output) for s in t.slaves] == [14, 14, 15, 14, 15, 15]
        assert [len(s.input) for s in t.slaves] == [20, 20, 21, 16, 21, 21]
        assert t.startup_written == 3  # Elmo's 0x60C2:1/2, Inovance's mode
        # the Nanotec's AssignActivate 0x330 asks 0x30 in ESC 0x0980 (SOEM writes 0x00):
        # written by the master's own datagram, the 0x300 drives left at 0x00, no warning
        assert emu.call(op="status")["cyclic_unit_control"] == [0, 0, 0x30, 0, 0, 0]
        assert t.warnings == [] and "warning" not in capfd.readouterr().err
        assert t.read_value(0, 0x60C2, 1, "u8") == 1  # the loop period [ms]
        assert t.read_value(1, 0x6060, 0, "i8") == 8
        g = DriveGroup.from_config(t, cfg.bus)
        assert g.present("torque_offset").tolist() == [False, True, True, False, True, True]
        assert g.present("error_code").tolist() == [False, True, True, False, True, True]
        assert any("axis 3" in line and "torque not mapped" in line for line in g.unavailable())
        g.set_mode(Mode.CSP)
        g.enable()
        assert g.all_in(State.OPERATION_ENABLED)
        q0 = g.q.copy()
        plant0 = np.array(emu.call(op="status")["q"])
        step = np.full(6, 0.05)
        statuses = []
        for k in range(400):
            g.command_position(q0 + step * min(1.0, k / 200))
            statuses.append(g.cycle())
            t.wait_next_cycle()
        assert statuses.count(STATUS_OK) >= 390
        np.testing.assert_allclose(g.q - q0, step, atol=3e-3)
        plant = np.array(emu.call(op="status")["q"])
        np.testing.assert_allclose(plant - plant0, step, atol=3e-3)
        # axis 3 (no 0x6077, fallback torque: current): its torque is its current x kt x gear
        d3 = cfg.bus.drives[3]
        assert t.torque_from_current.tolist() == [False, False, False, True, False, False]
        assert g.tau[3] != 0.0
        assert g.tau[3] == pytest.approx(g.current[3] * d3.torque_constant * d3.gear_ratio)
        g.disable()
    finally:
        t.close()


def _cycles_ok(t: EtherCATTransport, n: int) -> list[int]:
    out = []
    for _ in range(n):
        out.append(t.exchange())
        t.wait_next_cycle()
    return out


def test_power_cycled_drives_come_back_to_op_with_their_dc_and_start_up_values(mixed_bus) -> None:
    """The Inovance (DC-only, its mode set by a start-up SDO) and the Nanotec (0x0980 =
    0x30, SYNC0 fixed at 1 ms) lose power mid-run and come back in INIT with their start-up
    values, PDOs and DC gone: recovery programs them as the start did, and both reach OP."""
    master, cfg, emu = mixed_bus
    t = _transport(master, cfg, recover=True)
    try:
        t.open()
        written = t.startup_written
        for slave in (1, 2):
            emu.call(op="restart", slave=slave)
        status = emu.call(op="status")
        assert status["cyclic_unit_control"][2] == 0 and status["al_state"][1:3] == [1, 1]
        lost = t.check_bus()
        assert len(lost) == 2 and all("does not answer" in p for p in lost)
        notes = t.recover_slaves()
        assert [n for n in notes if "reconfigured" in n] == [
            f"slave 2 (joint_2) on {master} answered again and was reconfigured",
            f"slave 3 (joint_3) on {master} answered again and was reconfigured",
        ], notes
        assert t.check_bus() == []
        status = emu.call(op="status")
        assert status["al_state"] == [0x08] * 6
        assert status["cyclic_unit_control"] == [0, 0, 0x30, 0, 0, 0]
        assert t.startup_written == written + 1  # the Inovance's mode, once more
        assert t.read_value(1, 0x6060, 0, "i8") == 8
        assert set(_cycles_ok(t, 20)) == {STATUS_OK}
    finally:
        t.close()


def test_a_drive_that_cannot_be_configured_again_stays_out_of_op_named_in_one_line(
    mixed_bus,
) -> None:
    master, cfg, emu = mixed_bus
    t = _transport(master, cfg, recover=True)
    try:
        t.open()
        emu.call(op="restart", slave=1)
        emu.call(op="sdo_abort", slave=1, index=0x6060, sub=0, code=0x06090030)
        notes = t.recover_slaves()
        mine = [n for n in notes if n.startswith("slave 2 ")]
        assert mine and mine[0].startswith(
            f"slave 2 (joint_2) on {master} answered again but stays out of OP: "
        ), notes
        assert "0x6060" in mine[0] and all("\n" not in n for n in notes)
        status = emu.call(op="status")
        assert status["al_state"][1] == 0x02  # PRE-OP: no process data from a wrong drive
        assert [s for k, s in enumerate(status["al_state"]) if k != 1] == [0x08] * 5
    finally:
        t.close()


def test_a_fixed_pdo_the_master_would_write_is_refused_by_the_drive(mixed_bus) -> None:
    master, cfg, _emu = mixed_bus
    profiles = [profile(p) for p in MIXED]
    wrong = copy.deepcopy(ELMO)
    wrong["rx_pdos"][0]["fixed"] = False  # the real Elmo's 0x1605 is read-only
    profiles[0] = profile(wrong)
    t = _transport(master, cfg, profiles)
    with pytest.raises(SdoAbortError) as err:
        t.open()
    msg = str(err.value)
    assert (
        "0x1605" in msg
        and "0x06010002 attempt to write a read-only object" in msg
        and "\n" not in msg
    )


def test_a_layout_that_reads_back_different_is_refused_naming_axis_object_and_values(
    mixed_bus,
) -> None:
    master, cfg, _emu = mixed_bus
    profiles = [profile(p) for p in MIXED]
    wrong = copy.deepcopy(ELMO)
    entries = wrong["tx_pdos"][0]["entries"]
    entries[0], entries[2] = entries[2], entries[0]  # position and velocity swapped
    profiles[0] = profile(wrong)
    t = _transport(master, cfg, profiles)
    with pytest.raises(EtherCATError) as err:
        t.open()
    msg = str(err.value)
    assert msg.startswith("slave 1 (")
    assert "0x1A07 reads back [0x6064:00/32" in msg
    assert "expects [0x606C:00/32" in msg and "\n" not in msg


def test_op_without_the_dc_the_drive_requires_is_refused_with_its_al_code(mixed_bus) -> None:
    master, cfg, _emu = mixed_bus
    profiles = [profile(p) for p in MIXED]
    no_dc = copy.deepcopy(INOVANCE)
    del no_dc["dc"]  # the master thinks the drive runs free; the drive is DC-only
    profiles[1] = profile(no_dc)
    t = _transport(master, cfg, profiles)
    with pytest.raises(StateChangeError) as err:
        t.open()
    msg = str(err.value)
    assert "slave 2" in msg and "0x0030" in msg and "DC" in msg
    assert "slave 3" not in msg  # the Nanotec got its 1 ms SYNC0 with the shift


def test_safe_op_is_refused_when_0x0980_is_not_programmed_as_the_drive_says(mixed_bus) -> None:
    """The master's profile of the Nanotec says AssignActivate 0x0300 (low byte 0x00, what
    SOEM's dc_sync writes), the emulated drive's ESI 0x0330: nothing writes 0x30 to 0x0980
    and the drive refuses SAFE-OP with AL status 0x0030, as an SSC-based drive does."""
    master, cfg, emu = mixed_bus
    profiles = [profile(p) for p in MIXED]
    other = copy.deepcopy(NANOTEC)
    other["dc"]["assign_activate"] = 0x0300
    profiles[2] = profile(other)
    t = _transport(master, cfg, profiles)
    with pytest.raises(StateChangeError) as err:
        t.open()
    msg = str(err.value)
    assert msg.startswith("EtherCAT slaves did not reach SAFE-OP: slave 3 (")
    assert "0x0030" in msg and "slave 2" not in msg and "\n" not in msg
    assert emu.call(op="status")["cyclic_unit_control"][2] == 0


def test_a_0x0980_that_reads_back_different_is_refused_in_one_line(mixed_bus) -> None:
    """A profile asking a reserved bit of 0x0980 (0x80: an ESC keeps reserved bits 0): the
    write is read back, and the difference is one line naming the slave and its joint, the
    register, the expected and the found value, before SAFE-OP is asked for."""
    master, cfg, emu = mixed_bus
    profiles = [profile(p) for p in MIXED]
    other = copy.deepcopy(NANOTEC)
    other["dc"]["assign_activate"] = 0x0380
    profiles[2] = profile(other)
    t = _transport(master, cfg, profiles)
    with pytest.raises(RegisterMismatchError) as err:
        t.open()
    assert str(err.value) == (
        f"slave 3 (joint_3) on {master}: ESC register 0x0980 (cyclic unit control, "
        "AssignActivate 0x0380 of profile test_nanotec) reads back 0x00, expected 0x80"
    )
    assert max(emu.call(op="status")["highest_al_state"]) == 0x02  # PRE-OP: never further


def test_the_master_programs_the_sync0_cycle_its_profile_names(mixed_bus) -> None:
    master, cfg, _emu = mixed_bus
    profiles = [profile(p) for p in MIXED]
    other = copy.deepcopy(NANOTEC)
    other["dc"]["sync0_cycle_ns"] = 2_000_000  # the emulated Nanotec insists on 1 ms
    profiles[2] = profile(other)
    t = _transport(master, cfg, profiles)
    with pytest.raises(StateChangeError) as err:
        t.open()
    msg = str(err.value)
    assert "slave 3" in msg and "0x0030" in msg
    assert "slave 2" not in msg and "slave 1" not in msg


def test_a_profile_without_the_velocity_unit_is_refused_before_the_bus_opens(tmp_path) -> None:
    """A drive profile saying units.velocity unknown: the master refuses it in one line
    naming the joint and the profile, in its constructor (no socket, no frame)."""
    cfg = load_config(write_mixed_config(tmp_path))
    data = copy.deepcopy(NANOTEC)
    data["units"] = {"velocity": "unknown", "acceleration": "unknown"}
    profiles = [profile(p) for p in MIXED]
    profiles[2] = profile(data)
    with pytest.raises(ConfigError) as err:
        _transport("no-such-interface", cfg, profiles)
    assert str(err.value) == (
        "joint_3 (test_nanotec): the drive's velocity unit is not stated in its file; set "
        "units.velocity in the profile (counts/s or rpm) after checking the drive's manual"
    )
