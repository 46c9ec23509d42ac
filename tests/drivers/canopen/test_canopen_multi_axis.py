"""Multi-axis CANopen nodes (issue 25): the arm's six joints on three emulated two-axis
CANopen nodes (a SYNTHETIC profile, tests/support/profiles.py CAN_TWO_AXIS: none of the vendor
files describes a multi-axis device) on python-can's virtual bus. One node per device: one
NMT state, one heartbeat, one SDO server, one EMCY COB-ID; the CiA-402 state and the
process image per axis (axis k's objects at 0x6000 + 0x800·k, its own PDOs). A node fault
names every joint on it; an EMCY names its axis when the profile says in which byte, else
the master reads 0x603F of each axis by SDO."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from support.canopen import unique_channel, wait_for
from support.profiles import (
    CAN_TWO_AXIS,
    CAN_TWO_AXIS_NO_EMCY_AXIS,
    profile,
    write_can_two_axis_config,
)

from drivers.canopen import layout
from drivers.canopen.errors import CANopenError
from drivers.canopen.master import STATUS_HEARTBEAT_LOST, STATUS_NOT_OPERATIONAL
from drivers.cia402.drive_group import DriveGroup
from drivers.cia402.state_machine import Mode, State
from drivers.transport import STATUS_OK
from hofto_hw.cli import main
from hofto_hw.config.loader import dump_yaml, load_config


def _rig(tmp_path: Path, prof: dict | None = None):
    import can

    from drivers.sim.canopen_node import CanopenDrives
    from hofto_hw.runtime.build import build_emulated_drives

    cfg = load_config(write_can_two_axis_config(tmp_path, prof))
    channel = unique_channel()
    bus = can.Bus(interface="virtual", channel=channel)
    emu = CanopenDrives.for_bus(build_emulated_drives(cfg, external=False), bus, cfg.bus)
    return cfg, channel, bus, emu.start()


@pytest.fixture()
def two_axis(tmp_path: Path):
    cfg, channel, bus, emu = _rig(tmp_path)
    masters: list = []
    try:
        yield cfg, channel, emu, masters
    finally:
        for m in masters:
            m.close()
        emu.stop()
        bus.shutdown()


def _master(cfg, channel, masters):
    from drivers.canopen.master import CANopenTransport
    from drivers.cia402.profiles import profiles_for

    t = CANopenTransport(
        channel,
        cfg.bus.drives,
        cfg.cycle_time,
        list(cfg.robot.joints),
        can_interface="virtual",
        tpdo_deadline=0.05,  # generous: CI is a loaded 2-core machine
        heartbeat_time=0.05,
        heartbeat_timeout=0.5,
        sdo_timeout=2.0,
        profiles=profiles_for(cfg.bus.drives, "canopen"),
    )
    masters.append(t)
    return t


def _enabled(cfg, channel, masters):
    t = _master(cfg, channel, masters)
    t.open()
    g = DriveGroup.from_config(t, cfg.bus)
    g.configure(cfg.bus.drives)
    g.set_mode(Mode.CSP)
    g.enable()
    return t, g


def test_six_joints_on_three_two_axis_nodes(two_axis) -> None:
    cfg, channel, emu, masters = two_axis
    t = _master(cfg, channel, masters)
    assert t.n_axes == 6 and t.n_devices == 3 and t.node_ids == [1, 2, 3]
    assert t.wire.serve == ((0, 0), (0, 1), (1, 0), (1, 1), (2, 0), (2, 1))
    # RPDO1/2 of axis 0 and RPDO3/4 of axis 1 on one node: 2 x 15 bytes out, 2 x 15 in
    assert [t.wire.rx_size(d) for d in range(3)] == [30] * 3
    assert [t.wire.tx_size(d) for d in range(3)] == [30] * 3
    t.open()
    status = emu.status()
    assert status["nmt"] == [layout.NMT_OPERATIONAL] * 3  # three nodes, not six
    # PDO n of node 2: CiA 301's default COB-IDs, read back from the node
    assert [t.read_value(2, 0x1800 + k, 1, "u32") for k in range(4)] == [
        0x182, 0x282, 0x382, 0x482
    ]  # fmt: skip
    # joint 1's SDOs reach axis 1 of node 1 (0x6872), joint 0's axis 0 (0x6072)
    t.write_value(0, 0x6072, 0, "u16", 999)
    t.write_value(1, 0x6072, 0, "u16", 1234)
    assert t.read_value(0, 0x6072, 0, "u16") == 999
    assert t.read_value(1, 0x6072, 0, "u16") == 1234
    g = DriveGroup.from_config(t, cfg.bus)
    g.configure(cfg.bus.drives)
    g.set_mode(Mode.CSP)
    g.enable()
    assert g.all_in(State.OPERATION_ENABLED)
    assert emu.status()["drive_state"] == [int(State.OPERATION_ENABLED)] * 6
    q0 = g.q.copy()
    plant0 = np.array(emu.status()["q"])
    step = np.array([0.02, 0.03, 0.04, 0.05, 0.06, 0.07])  # a different step per joint
    statuses = []
    for k in range(300):
        g.command_position(q0 + step * min(1.0, k / 60))
        t.wait_next_cycle()
        statuses.append(g.cycle())
    assert statuses.count(STATUS_OK) >= 270, statuses
    np.testing.assert_allclose(g.q - q0, step, atol=5e-3)
    plant = np.array(emu.status()["q"])
    np.testing.assert_allclose(plant - plant0, step, atol=5e-3)  # each joint its own
    assert not g.any_fault() and not t.problems()


def test_a_silent_heartbeat_latches_a_fault_naming_both_joints(two_axis) -> None:
    cfg, channel, emu, masters = two_axis
    t, g = _enabled(cfg, channel, masters)
    emu.control({"op": "heartbeat", "node": 1, "on": False})  # node 2: joints 3 and 4
    statuses: list[int] = []

    def lost() -> bool:
        t.wait_next_cycle()
        statuses.append(g.cycle())
        return statuses[-1] == STATUS_HEARTBEAT_LOST

    wait_for(lost, 10.0, "heartbeat loss")
    problems = t.problems()
    assert problems[0].startswith("node 2 (joint_3, joint_4): heartbeat lost"), problems
    assert not [p for p in problems if "node 1" in p or "node 3" in p], problems
    assert t.node_fault_axes().tolist() == [False, False, True, True, False, False]
    # latched: the heartbeat comes back, the bus status is fine again, the fault of the
    # run stays (safety latches on the status); the master itself reports while it lasts
    emu.control({"op": "heartbeat", "node": 1, "on": True})
    wait_for(lambda: not t.problems(), 10.0, "heartbeat back")


def test_nmt_stop_of_a_node_names_both_its_joints(two_axis) -> None:
    cfg, channel, emu, masters = two_axis
    t, g = _enabled(cfg, channel, masters)
    t.nmt("stop", axis=5)  # joint 6: node 3, which also runs joint 5

    def left() -> bool:
        t.wait_next_cycle()
        return g.cycle() == STATUS_NOT_OPERATIONAL

    wait_for(left, 10.0, "node 3 stopped")
    assert "node 3 (joint_5, joint_6): left operational, heartbeat reports stopped" in (
        t.problems()
    )
    assert emu.status()["nmt"] == [layout.NMT_OPERATIONAL] * 2 + [layout.NMT_STOPPED]


def test_an_emcy_names_its_axis_and_joint(two_axis) -> None:
    cfg, channel, emu, masters = two_axis
    t, g = _enabled(cfg, channel, masters)
    assert emu.control({"op": "emcy", "node": 2, "axis": 1, "code": 0x2310})["ok"]
    for _ in range(2000):  # wait for the state, not for a time
        t.wait_next_cycle()
        g.cycle()
        if g.any_fault() and int(t.tx["error_code"][5]):
            break
    assert g.states.tolist().count(State.FAULT) == 1 and g.states[5] == State.FAULT
    assert int(t.tx["error_code"][5]) == 0x2310 and int(t.tx["error_code"][4]) == 0
    msgs = t.emergency_messages()
    assert msgs[0].startswith("node 3 axis 1 (joint_6): EMCY 0x2310"), msgs
    assert t.problems() == [
        "node 3 axis 1 (joint_6): emergency 0x2310 continuous over-current"
    ] or t.problems()[0].startswith("node 3 axis 1 (joint_6): emergency 0x2310")


def test_an_emcy_without_an_axis_is_placed_by_0x603f(tmp_path: Path) -> None:
    cfg, channel, bus, emu = _rig(tmp_path, CAN_TWO_AXIS_NO_EMCY_AXIS)
    masters: list = []
    try:
        t, g = _enabled(cfg, channel, masters)
        emu.control({"op": "emcy", "node": 0, "axis": 1, "code": 0x2310})
        for _ in range(2000):
            t.wait_next_cycle()
            g.cycle()
            if g.any_fault() and t.emergency_messages():
                break
        assert g.states[1] == State.FAULT and g.states[0] != State.FAULT
        # the EMCY says node 1 only: both axes read its code, 0x603F by SDO tells which
        assert t.emergency_messages()[0].startswith("node 1 (joint_1, joint_2): EMCY 0x2310")
        problems = t.problems()
        assert len(problems) == 1, problems
        assert problems[0].startswith("node 1 axis 1 (joint_2): emergency 0x2310")
        assert problems[0].endswith("(0x603F)")
    finally:
        for m in masters:
            m.close()
        emu.stop()
        bus.shutdown()


# ------------------------------------------------------------------ COB-IDs


def test_the_cob_id_rule_and_clashes() -> None:
    assert [layout.pdo_cob_base("tpdo", n) for n in range(1, 9)] == [
        0x180, 0x280, 0x380, 0x480, 0x1C0, 0x2C0, 0x3C0, 0x4C0
    ]  # fmt: skip
    assert layout.pdo_cob_base("rpdo", 5) == 0x240
    with pytest.raises(ValueError, match=r"PDOs 1\.\.8"):
        layout.pdo_cob_base("rpdo", 9)
    # node 1's TPDO5 borrows node 65's TPDO1 COB-ID: a clash when node 65 is on the bus
    node1 = (1, "node 1", [("TPDO5", layout.pdo_cob_base("tpdo", 5) + 1)])
    node65 = (65, "node 65", [("TPDO1", 0x180 + 65)])
    assert layout.cob_id_clashes([node1]) == []
    clash = layout.cob_id_clashes([node1, node65])
    assert clash == ["node 65 TPDO1: COB-ID 0x1C1 is already node 1 TPDO5's"]
    # a PDO on another node's EMCY / SDO COB-ID
    assert layout.cob_id_clashes([(2, "node 2", [("TPDO1", 0x81)]), (1, "node 1", [])]) == [
        "node 1 EMCY: COB-ID 0x081 is already node 2 TPDO1's"
    ]


def test_the_master_refuses_clashing_cob_ids(tmp_path: Path) -> None:
    from drivers.canopen.master import CANopenTransport

    bad = yaml.safe_load(yaml.safe_dump(CAN_TWO_AXIS))
    bad["canopen"]["tpdo"][3]["cob_id_base"] = 0x180 + 1  # TPDO4 of node n = TPDO1 of n + 1
    prof = profile(bad)
    cfg = load_config(write_can_two_axis_config(tmp_path))
    with pytest.raises(CANopenError, match=r"node 2 \(joint_3, joint_4\) TPDO1: COB-ID 0x182"):
        CANopenTransport(
            "x", cfg.bus.drives, cfg.cycle_time, list(cfg.robot.joints),
            can_interface="virtual", profiles=[prof] * 6,
        )  # fmt: skip


# ------------------------------------------------------------------ config check


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        ("one_axis_profile", "bus.drives[1].device_axis 1: profile one_axis has 1 axis(es), 0..0"),
        ("device_gap", "drives[2].device: 2, but the next device in bus order is 1"),
        ("same_axis", "drives[1]: device 0 axis 0 already drives joint 0"),
        ("other_profile", "drives[1].profile"),
        ("node_ids", "canopen.node_ids has 6 ids for 6 drives on 3 devices (one node id per"),
        (
            "cob_clash",
            "bus.canopen: node 2 (bus.drives[2], bus.drives[3]) TPDO1: COB-ID 0x182 is already "
            "node 1 (bus.drives[0], bus.drives[1]) TPDO4's",
        ),
    ],
)
def test_a_bad_multi_axis_can_bus_is_refused_in_one_line(
    tmp_path: Path, capsys, edit: str, message: str
) -> None:
    path = write_can_two_axis_config(tmp_path)
    assert main(["config", "check", str(path)]) == 0, capsys.readouterr().err
    capsys.readouterr()
    raw = yaml.safe_load(path.read_text())
    drives = raw["bus"]["drives"]
    if edit == "one_axis_profile":  # device 0 axis 1, but the profile has one axis
        single = dict(CAN_TWO_AXIS) | {"axes": 1, "name": "one_axis"}
        single["rx_pdos"] = CAN_TWO_AXIS["rx_pdos"][:2]
        single["tx_pdos"] = CAN_TWO_AXIS["tx_pdos"][:2]
        single["canopen"] = dict(CAN_TWO_AXIS["canopen"])
        single["canopen"]["rpdo"] = CAN_TWO_AXIS["canopen"]["rpdo"][:2]
        single["canopen"]["tpdo"] = CAN_TWO_AXIS["canopen"]["tpdo"][:2]
        prof = tmp_path / "one_axis.yaml"
        prof.write_text(dump_yaml(single, sort_keys=False))
        for d in drives:
            d["profile"] = str(prof)
    elif edit == "device_gap":
        drives[2]["device"] = 2
    elif edit == "same_axis":
        drives[1]["device_axis"] = 0
    elif edit == "other_profile":
        drives[1]["profile"] = "zeroerr_erob"
    elif edit == "cob_clash":  # TPDO4 of node n on TPDO1 of node n + 1
        bad = yaml.safe_load(yaml.safe_dump(CAN_TWO_AXIS))
        bad["canopen"]["tpdo"][3]["cob_id_base"] = 0x181
        prof = tmp_path / "clash.yaml"
        prof.write_text(dump_yaml(bad, sort_keys=False))
        for d in drives:
            d["profile"] = str(prof)
    else:
        raw["bus"]["canopen"]["node_ids"] = [1, 2, 3, 4, 5, 6]
    path.write_text(dump_yaml(raw, sort_keys=False))
    code = main(["config", "check", str(path)])
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert message in err and "\n" not in err and "Traceback" not in err


# ------------------------------------------------------------- drive check, bus scan


@pytest.mark.parametrize("can_interface", ["virtual", "udp_multicast"])
def test_drive_check_runs_a_two_axis_profile_on_three_nodes(
    tmp_path: Path, capsys, can_interface: str
) -> None:
    import json

    prof = tmp_path / "two_axis.yaml"
    prof.write_text(dump_yaml(CAN_TWO_AXIS, sort_keys=False))
    args = ["drive", "check", str(prof), "--emulated", "--axes", "6", "--json"]
    code = main([*args, "--can-interface", can_interface])
    out = capsys.readouterr().out
    assert code == 0, out
    r = json.loads(out)
    assert r["bus"] == "canopen" and r["can_interface"] == can_interface
    assert r["operational"] and r["enabled"] and not r["faults"]
    assert r["devices"] == [{"device": d, "axis": k} for d in range(3) for k in range(2)]
    assert r["process_image_bytes"] == [{"rx": 30, "tx": 30}] * 6
    assert r["pdos"][1] == {
        "rx": ["0x1600", "0x1601", "0x1602", "0x1603"],
        "tx": ["0x1A00", "0x1A01", "0x1A02", "0x1A03"],
    }
    assert all(abs(m - 0.05) <= 0.005 for m in r["moved_rad"]), r["moved_rad"]


def _layout(p) -> tuple:
    """PDOs in order: index, fixed or configurable (the scan's CiA 301 probe), entries."""
    return tuple(
        [(x.index, x.fixed, [(e.index, e.subindex, e.bits) for e in x.entries]) for x in pdos]
        for pdos in (p.rx_pdos, p.tx_pdos)
    )


def test_scan_of_two_axis_nodes_drafts_the_two_axis_profile(
    two_axis, tmp_path: Path, capsys
) -> None:
    from hofto_hw.config.drive_profile import load_profile

    _cfg, channel, _emu, _masters = two_axis
    out = tmp_path / "scanned"
    code = main(["bus", "scan", "--interface", "virtual", "--channel", channel, "-o", str(out)])
    assert code == 0, capsys.readouterr().err
    bus = yaml.safe_load((out / "bus.yaml").read_text())["bus"]
    assert bus["transport"] == "canopen" and bus["canopen"]["node_ids"] == [1, 2, 3]
    assert [(d["device"], d["device_axis"]) for d in bus["drives"]] == [
        (dev, k) for dev in range(3) for k in range(2)
    ]
    assert len({d["profile"] for d in bus["drives"]}) == 1
    want, got = profile(CAN_TWO_AXIS), load_profile(out / f"{bus['drives'][0]['profile']}.yaml")
    assert got.axes == 2
    assert _layout(got) == _layout(want)
    assert got.field_offsets("rx", 1)["controlword"] == (120, 16)  # axis 1 after axis 0's 15 B
    for side in ("rpdo", "tpdo"):
        assert [c.model_dump() for c in getattr(got.canopen, side)] == [
            c.model_dump() for c in getattr(want.canopen, side)
        ]
    assert got.canopen.max_entries == want.canopen.max_entries
    # the EMCY's axis byte is not in the dictionary: a scan cannot know it
    assert got.canopen.emcy_axis_byte is None
