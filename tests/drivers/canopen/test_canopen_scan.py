"""``hofto-hw bus scan`` of an emulated CANopen bus of three drive models (virtual bus): the
drafts have the layout, communication parameters and start-up list of the profiles the
nodes were built from; two nodes with one node id are refused in one line."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from support.canopen import CONFIG, unique_channel
from support.profiles import CAN_MIXED, profile, write_mixed_config

from hofto_hw.cli import main
from hofto_hw.config.drive_profile import load_profile


@pytest.fixture()
def nodes(tmp_path: Path):
    import can

    from drivers.sim.canopen_node import CanopenDrives
    from hofto_hw.config.loader import load_config
    from hofto_hw.runtime.build import build_emulated_drives

    cfg = load_config(write_mixed_config(tmp_path, CAN_MIXED, base=CONFIG))
    channel = unique_channel()
    buses, emus = [], []

    def start(node_ids=None):
        bus = can.Bus(interface="virtual", channel=channel)
        emu = CanopenDrives(build_emulated_drives(cfg, external=False), bus, node_ids).start()
        buses.append(bus)
        emus.append(emu)
        return emu

    try:
        yield channel, start
    finally:
        for e in emus:
            e.stop()
        for b in buses:
            b.shutdown()


def _layout(p) -> tuple:
    """PDOs in order: index, fixed or configurable, entries."""
    return tuple(
        [(x.index, x.fixed, [(e.index, e.subindex, e.bits) for e in x.entries]) for x in pdos]
        for pdos in (p.rx_pdos, p.tx_pdos)
    )


def test_scan_gives_back_the_profiles_of_the_nodes(nodes, tmp_path: Path, capsys) -> None:
    channel, start = nodes
    emus = start()
    cobs = _cob_ids(emus)
    out = tmp_path / "scan"
    code = main(["bus", "scan", "--interface", "virtual", "--channel", channel, "-o", str(out)])
    assert code == 0, capsys.readouterr().err
    bus = yaml.safe_load((out / "bus.yaml").read_text())["bus"]
    assert bus["transport"] == "canopen" and bus["canopen"]["node_ids"] == [1, 2, 3, 4, 5, 6]
    fixed = [x.fixed for d in CAN_MIXED for x in profile(d).rx_pdos + profile(d).tx_pdos]
    assert True in fixed and False in fixed  # the bus mixes fixed and configurable PDOs
    # the probe made each PDO invalid and restored it: the nodes are as they were
    assert _cob_ids(emus) == cobs
    names = [d["profile"] for d in bus["drives"]]
    assert len(set(names)) == 3 and names[:3] == names[3:]
    for want_data, name in zip(CAN_MIXED, names, strict=True):
        want, got = profile(want_data), load_profile(out / f"{name}.yaml")
        assert _layout(got) == _layout(want), want.name
        assert [c.model_dump() for c in got.canopen.rpdo] == [
            c.model_dump() for c in want.canopen.rpdo
        ]
        assert [c.model_dump() for c in got.canopen.tpdo] == [
            c.model_dump() for c in want.canopen.tpdo
        ]
        assert got.canopen.max_entries == want.canopen.max_entries
        assert [(w.index, w.value, w.transition) for w in got.startup] == [
            (w.index, w.value, w.transition) for w in want.startup
        ]


def test_two_nodes_with_one_node_id_are_refused(nodes, tmp_path: Path, capsys) -> None:
    channel, start = nodes
    start()
    start([7, 8, 9, 10, 11, 3])  # the sixth drive of the second line claims node id 3
    code = main(
        ["bus", "scan", "--interface", "virtual", "--channel", channel, "-o", str(tmp_path / "x")]
    )
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert "two drives claim node id 3" in err and "\n" not in err
    assert not (tmp_path / "x").exists()


def _cob_ids(emu) -> list[list[int]]:
    """Every node's PDO COB-IDs (0x1400../0x1800.. sub 1), as the nodes hold them."""
    from drivers.sim.canopen_node import pdo_objects

    with emu.lock:
        return [
            [od.get(comm, 1) for _name, comm, *_rest in pdo_objects(prof)]
            for od, prof in zip(emu.ods, emu.profiles, strict=True)
        ]


def test_mapping_writes_follow_cia_301(nodes) -> None:
    """A node impersonating a profile: a fixed mapping refuses a write (0x06010002 read
    only); a configurable one refuses it while its PDO is valid (0x06090030, CANopenNode's
    code) and takes it once the PDO is made invalid (COB-ID bit 31); operational refuses
    every mapping write (0x08000022)."""
    from drivers.sim.object_dictionary import SdoAbort

    _channel, start = nodes
    emu = start()
    tech = emu.ods[2]  # test_can_technosoft: TPDO1 0x1A00 fixed, TPDO2 0x1A01 configurable
    with emu.lock:

        def code(index: int, value: int) -> int | None:
            try:
                tech.write(index, 0, bytes([value]))
            except SdoAbort as a:
                return a.code
            return None

        n = tech.get(0x1A01, 0)
        assert tech.get(0x1801, 1) & 0x80000000 == 0  # enabled by default
        assert code(0x1A00, tech.get(0x1A00, 0)) == 0x06010002
        assert code(0x1A01, n) == 0x06090030
        tech.write(0x1801, 1, (tech.get(0x1801, 1) | 0x80000000).to_bytes(4, "little"))
        assert code(0x1A01, n) is None and tech.get(0x1A01, 0) == n
        assert code(0x1A00, tech.get(0x1A00, 0)) == 0x06010002  # fixed stays fixed
        tech.pdo_locked = True  # NMT operational
        assert code(0x1A01, n) == 0x08000022
