"""Multi-axis drives (issue 25): the arm's six joints on three emulated two-axis EtherCAT
slaves (a SYNTHETIC profile: none of the vendor files describes a multi-axis device).
``bus.drives[i].device`` / ``device_axis`` say which slave and which CiA-402 axis drives
joint i; the master configures each slave once, reads its layout back and builds the
process image per axis (axis k's objects at 0x6000 + 0x800·k); SDOs of a joint reach its
axis's objects. The bus tests need root (veth, raw sockets); a bad multi-axis bus is refused
by `config check` in one line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from support.profiles import TWO_AXIS, write_two_axis_config
from support.rootnet import emulator, sim_ethercat_args, veth_pair

from drivers.cia402.drive_group import DriveGroup
from drivers.cia402.state_machine import Mode, State
from drivers.ethercat.master import EtherCATTransport
from drivers.transport import STATUS_OK
from hofto_hw.cli import main
from hofto_hw.config.loader import dump_yaml, load_config


@pytest.fixture()
def two_axis_bus(tmp_path: Path):
    with veth_pair("xm", "xs") as (master, slave):
        config = write_two_axis_config(tmp_path, master)
        with emulator(sim_ethercat_args(slave, config), tmp_path, timeout=30.0) as emu:
            yield master, load_config(config), emu


def _transport(cfg) -> EtherCATTransport:
    return EtherCATTransport.from_config(cfg.bus, list(cfg.robot.joints), cycle_time=cfg.cycle_time)


@pytest.mark.root
def test_six_joints_on_three_two_axis_slaves(two_axis_bus) -> None:
    master, cfg, emu = two_axis_bus
    t = _transport(cfg)
    try:
        t.open()
        assert len(t.slaves) == 3 and t.n_axes == 6
        w = t.wire
        assert w.serve == ((0, 0), (0, 1), (1, 0), (1, 1), (2, 0), (2, 1))
        assert [lay.rx_pdos for lay in w.layouts] == [(0x1600, 0x1610)] * 3
        assert [lay.tx_pdos for lay in w.layouts] == [(0x1A00, 0x1A10)] * 3
        # one slave carries both axes' process data: 2 x 15 bytes out, 2 x 21 in
        assert [(len(s.output), len(s.input)) for s in t.slaves] == [(30, 42)] * 3
        assert all(w.present["torque_offset"]) and all(w.present["velocity"])
        # joint 1's SDOs reach axis 1 of slave 1 (0x6872), joint 0's axis 0 (0x6072)
        t.write_value(0, 0x6072, 0, "u16", 999)
        t.write_value(1, 0x6072, 0, "u16", 1234)
        assert t.read_value(0, 0x6072, 0, "u16") == 999
        assert t.read_value(1, 0x6072, 0, "u16") == 1234
        g = DriveGroup.from_config(t, cfg.bus)
        g.configure(cfg.bus.drives)  # identity and ratings per joint, limits per axis
        g.set_mode(Mode.CSP)
        g.enable()
        assert g.all_in(State.OPERATION_ENABLED)
        q0 = g.q.copy()
        plant0 = np.array(emu.call(op="status")["q"])
        step = np.array([0.02, 0.03, 0.04, 0.05, 0.06, 0.07])  # a different step per joint
        statuses = []
        for k in range(500):
            g.command_position(q0 + step * min(1.0, k / 200))
            statuses.append(g.cycle())
            t.wait_next_cycle()
        assert statuses.count(STATUS_OK) >= 490
        np.testing.assert_allclose(g.q - q0, step, atol=3e-3)
        plant = np.array(emu.call(op="status")["q"])
        np.testing.assert_allclose(plant - plant0, step, atol=3e-3)  # each joint its own
        g.disable()
    finally:
        t.close()


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        ("one_axis_profile", "bus.drives[1].device_axis 1: profile one_axis has 1 axis(es), 0..0"),
        ("device_gap", "drives[2].device: 2, but the next device in bus order is 1"),
        ("same_axis", "drives[1]: device 0 axis 0 already drives joint 0"),
        ("other_profile", "drives[1].profile"),
        (
            "sim_transport",
            "multi-axis drives run on transport ethercat or canopen only (got 'sim')",
        ),
    ],
)
def test_a_bad_multi_axis_bus_is_refused_in_one_line(
    tmp_path: Path, capsys, edit: str, message: str
) -> None:
    import yaml

    path = write_two_axis_config(tmp_path)
    load_config(path)  # valid as written
    raw = yaml.safe_load(path.read_text())
    drives = raw["bus"]["drives"]
    if edit == "one_axis_profile":  # device 0 axis 1, but the profile has one axis
        single = dict(TWO_AXIS) | {"axes": 1, "name": "one_axis"}
        single["rx_pdos"] = TWO_AXIS["rx_pdos"][:1]
        single["tx_pdos"] = TWO_AXIS["tx_pdos"][:1]
        prof = tmp_path / "one_axis.yaml"
        prof.write_text(dump_yaml(single, sort_keys=False))
        for d in drives:
            d["profile"] = str(prof)
    elif edit == "device_gap":
        drives[2]["device"] = 2
    elif edit == "same_axis":
        drives[1]["device_axis"] = 0
    elif edit == "other_profile":
        drives[1]["profile"] = "elmo_gold"
    else:
        raw["bus"]["transport"] = "sim"
    path.write_text(dump_yaml(raw, sort_keys=False))
    code = main(["config", "check", str(path)])
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert message in err and "\n" not in err and "Traceback" not in err


@pytest.mark.root
def test_drive_check_runs_a_two_axis_profile_on_three_slaves(tmp_path: Path, capsys) -> None:
    prof = tmp_path / "two_axis.yaml"
    prof.write_text(dump_yaml(TWO_AXIS, sort_keys=False))
    code = main(["drive", "check", str(prof), "--emulated", "--axes", "6", "--json"])
    out = capsys.readouterr().out
    assert code == 0, out
    r = json.loads(out)
    assert r["operational"] and r["enabled"] and not r["faults"]
    assert r["devices"] == [{"device": d, "axis": k} for d in range(3) for k in range(2)]
    assert r["process_image_bytes"] == [{"rx": 30, "tx": 42}] * 6
    assert r["pdos"][1] == {"rx": ["0x1600", "0x1610"], "tx": ["0x1A00", "0x1A10"]}
    assert all(abs(m - 0.05) <= 0.005 for m in r["moved_rad"])


@pytest.mark.root
def test_scan_of_two_axis_slaves_drafts_a_two_axis_profile(two_axis_bus, tmp_path, capsys) -> None:
    import yaml

    from hofto_hw.config.drive_profile import load_profile

    master, _cfg, _emu = two_axis_bus
    out = tmp_path / "scanned"
    code = main(["bus", "scan", "--iface", master, "-o", str(out)])
    assert code == 0, capsys.readouterr().err
    bus = yaml.safe_load((out / "bus.yaml").read_text())["bus"]
    # one joint per axis of each slave, one draft for the model
    assert [(d["device"], d["device_axis"]) for d in bus["drives"]] == [
        (dev, k) for dev in range(3) for k in range(2)
    ]
    got = load_profile(out / f"{bus['drives'][0]['profile']}.yaml")
    assert got.axes == 2
    assert [(p.index, p.fixed) for p in got.rx_pdos] == [(0x1600, False), (0x1610, False)]
    assert got.field_offsets("rx", 1)["controlword"] == (120, 16)


@pytest.mark.root
def test_a_fault_on_axis_1_of_a_slave_is_named_by_slave_axis_and_joint(two_axis_bus) -> None:
    _master, cfg, emu = two_axis_bus
    t = _transport(cfg)
    try:
        t.open()
        g = DriveGroup.from_config(t, cfg.bus)
        g.set_mode(Mode.CSP)
        g.enable()
        assert emu.call(op="drive_fault", slave=5, code=0x2310)["ok"]  # joint 6: slave 3 axis 1
        for _ in range(2000):  # wait for the state, not for a time
            g.command_position(g.q.copy())
            g.cycle()
            t.wait_next_cycle()
            if g.any_fault():
                break
        assert g.states.tolist().count(State.FAULT) == 1 and g.states[5] == State.FAULT
        faults = t.drive_faults()
        assert len(faults) == 1
        assert faults[0].startswith("slave 3 axis 1 (joint_6)") and "0x2310" in faults[0]
    finally:
        t.close()
