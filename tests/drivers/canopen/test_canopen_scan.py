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

    try:
        yield channel, start
    finally:
        for e in emus:
            e.stop()
        for b in buses:
            b.shutdown()


def _layout(p) -> tuple:
    return tuple(
        [(x.index, [(e.index, e.subindex, e.bits) for e in x.entries]) for x in pdos]
        for pdos in (p.rx_pdos, p.tx_pdos)
    )


def test_scan_gives_back_the_profiles_of_the_nodes(nodes, tmp_path: Path, capsys) -> None:
    channel, start = nodes
    start()
    out = tmp_path / "scan"
    code = main(["bus", "scan", "--interface", "virtual", "--channel", channel, "-o", str(out)])
    assert code == 0, capsys.readouterr().err
    bus = yaml.safe_load((out / "bus.yaml").read_text())["bus"]
    assert bus["transport"] == "canopen" and bus["canopen"]["node_ids"] == [1, 2, 3, 4, 5, 6]
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
