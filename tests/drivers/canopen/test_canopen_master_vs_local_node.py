"""Our master against drives emulated by the independent `canopen` library: LocalNode with
the object dictionary of our EDS (SDO server, NMT slave, heartbeat producer), plus the
glue LocalNode lacks: boot-up on a received NMT reset, a minimal CiA-402 state machine and
TPDOs sent on each SYNC, all through canopen's own PDO objects."""

from __future__ import annotations

import struct
from collections.abc import Iterator

import pytest
from support.canopen import ROOT, load_cfg, unique_channel

from drivers.cia402.drive_group import DriveGroup
from drivers.cia402.state_machine import Mode, State

canopen = pytest.importorskip("canopen")
EDS = str(ROOT / "configs" / "canopen" / "emulated_drive.eds")
_SOD, _RTSO, _SO, _OE = 0x0250, 0x0231, 0x0233, 0x0237  # + remote, voltage where powered


def _next(sw: int, cw: int) -> int:
    if not cw & 0x02:
        return _SOD  # disable voltage
    if cw & 0x8F == 0x06 and sw in (_SOD, _SO, _OE):
        return _RTSO
    if cw & 0x8F == 0x07 and sw in (_RTSO, _OE):
        return _SO
    if cw & 0x8F == 0x0F and sw == _SO:
        return _OE
    return sw


class GluedNode:
    """One LocalNode plus SYNC/TPDO glue; the drive is ideal (position = target)."""

    def __init__(self, net, node_id: int, drive) -> None:
        self.node = canopen.LocalNode(node_id, canopen.import_od(EDS, node_id))
        net.add_node(self.node)
        for (index, sub), value in {
            (0x1018, 1): drive.identity.vendor_id,
            (0x1018, 2): drive.identity.product_code,
            (0x6076, 0): round(drive.rated_torque),
            (0x6075, 0): round(drive.rated_current),
        }.items():
            self.node.set_data(index, sub, struct.pack("<I", value))
        self.sw = _SOD
        self.ready = False
        self.syncs = 0
        net.subscribe(0x000, self.on_nmt)
        net.subscribe(0x080, self.on_sync)

    def on_nmt(self, _id, data, _ts) -> None:
        if self.node.nmt.state == "INITIALISING":  # LocalNode sends no boot-up itself
            self.node.nmt.send_command(0x82)  # boot-up message
            self.node.nmt.send_command(0x80)  # pre-operational, heartbeat from 0x1017
            self.ready = False
        elif self.node.nmt.state == "OPERATIONAL" and not self.ready:
            self.node.rpdo.read()  # mapping and COB-IDs as our master wrote them
            self.node.tpdo.read()
            self.ready = True

    def on_sync(self, _id, _data, _ts) -> None:
        if not self.ready:
            return
        self.syncs += 1
        r1, r2 = self.node.rpdo[1], self.node.rpdo[2]
        self.sw = _next(self.sw, r1["controlword"].raw)
        t1, t2 = self.node.tpdo[1], self.node.tpdo[2]
        t1["statusword"].raw = self.sw
        t1["position actual value"].raw = r1["target position"].raw
        t1["torque actual value"].raw = r2["target torque"].raw
        t2["modes of operation display"].raw = r2["modes of operation"].raw
        t1.transmit()
        t2.transmit()


@pytest.fixture()
def local_nodes() -> Iterator[tuple]:
    cfg = load_cfg()
    channel = unique_channel("local")
    net = canopen.Network()
    net.NOTIFIER_CYCLE = 0.05  # quick teardown
    net.connect(interface="virtual", channel=channel)
    nodes = [GluedNode(net, i + 1, d) for i, d in enumerate(cfg.bus.drives)]
    try:
        yield cfg, channel, nodes
    finally:
        for g in nodes:
            g.node.nmt.stop_heartbeat()
        net.disconnect()


def test_master_on_canopen_local_nodes_identity_mapping_enable(local_nodes) -> None:
    from drivers.canopen.master import CANopenTransport

    cfg, channel, nodes = local_nodes
    t = CANopenTransport(
        channel,
        cfg.bus.drives,
        1 / 200,
        list(cfg.robot.joints),
        can_interface="virtual",
        tpdo_deadline=0.05,
        heartbeat_timeout=0.5,
        sdo_timeout=2.0,  # LocalNode answers from canopen's notifier thread: slow under load
    )
    try:
        t.open()
        for g in nodes:  # what LocalNode stored is what we mapped
            tp = g.node.tpdo[1]
            assert tp.cob_id == 0x180 + g.node.id and tp.trans_type == 1
            assert [v.index for v in tp] == [0x6041, 0x6064, 0x6077]
            assert [v.index for v in g.node.rpdo[2]] == [0x60FF, 0x6071, 0x6060]
            assert g.node.nmt.state == "OPERATIONAL"
        assert t.read_value(5, 0x1018, 2, "u32") == cfg.bus.drives[5].identity.product_code
        grp = DriveGroup.from_config(t, cfg.bus)
        grp.configure(cfg.bus.drives)
        assert struct.unpack("<H", nodes[0].node.get_data(0x6066, 0))[0] == 10
        grp.set_mode(Mode.CSP)
        grp.enable()
        assert grp.all_in(State.OPERATION_ENABLED)
        assert all(g.sw == _OE for g in nodes)
    finally:
        t.close()


def test_wrong_identity_on_a_local_node_is_named(local_nodes) -> None:
    from drivers.canopen.errors import IdentityMismatchError
    from drivers.canopen.master import CANopenTransport

    cfg, channel, nodes = local_nodes
    nodes[3].node.set_data(0x1018, 1, struct.pack("<I", 0x12345678))
    t = CANopenTransport(
        channel,
        cfg.bus.drives,
        1 / 200,
        list(cfg.robot.joints),
        can_interface="virtual",
        sdo_timeout=2.0,
    )
    with pytest.raises(
        IdentityMismatchError,
        match=r"node 4 \(joint_4\) reports vendor id "
        r"0x12345678 \(0x1018:1\), expected 0x00000DEC",
    ):
        t.open()
