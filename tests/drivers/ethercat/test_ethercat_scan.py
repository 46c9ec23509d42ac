"""``hofto-hw bus scan`` of an emulated EtherCAT bus of six different drive models (root):
the draft profiles it writes have the layout, DC and start-up list of the profiles the
emulated drives were built from; the ``bus:`` section names them in line order."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from support.profiles import MIXED, profile, write_mixed_config
from support.rootnet import emulator, sim_ethercat_args, veth_pair

from drivers.cia402.scan import ScanError, check_unique
from hofto_hw.cli import main
from hofto_hw.config.drive_profile import load_profile


def _layout(p) -> tuple:
    """PDOs in order: index, fixed or configurable, entries."""
    return (
        [(x.index, x.fixed, [(e.index, e.subindex, e.bits) for e in x.entries])
         for x in p.rx_pdos],
        [(x.index, x.fixed, [(e.index, e.subindex, e.bits) for e in x.entries])
         for x in p.tx_pdos],
    )  # fmt: skip


def _dc(p) -> tuple | None:
    return None if p.dc is None else (p.dc.assign_activate, p.dc.sync0_cycle_ns,
                                      p.dc.sync0_shift_ns)  # fmt: skip


def _startup(p) -> list:
    return [(w.index, w.subindex, w.value, w.bits, w.transition) for w in p.startup]


@pytest.mark.root
def test_scan_of_a_mixed_bus_gives_back_the_profiles_of_its_drives(tmp_path: Path, capsys) -> None:
    config = write_mixed_config(tmp_path)
    out = tmp_path / "scanned"
    with (
        veth_pair("sm", "ss") as (master, slave),
        emulator(sim_ethercat_args(slave, config), tmp_path, timeout=30.0),
    ):
        code = main(["bus", "scan", "--iface", master, "-o", str(out)])
        assert code == 0, capsys.readouterr().err
        again = main(["bus", "scan", "--iface", master, "-o", str(out)])
        err = capsys.readouterr().err.strip()
        assert again == 2 and "exists; not overwritten" in err and "\n" not in err
    fixed = [x.fixed for d in MIXED for x in profile(d).rx_pdos + profile(d).tx_pdos]
    assert True in fixed and False in fixed  # the bus mixes fixed and configurable PDOs
    bus = yaml.safe_load((out / "bus.yaml").read_text())["bus"]
    assert bus["transport"] == "ethercat" and bus["interface"] == master
    assert len(bus["drives"]) == 6
    for want_data, drive in zip(MIXED, bus["drives"], strict=True):
        want = profile(want_data)
        got = load_profile(out / f"{drive['profile']}.yaml")
        assert got.identity.vendor_id == want.identity.vendor_id
        assert got.identity.product_code == want.identity.product_code
        assert _layout(got) == _layout(want), want.name
        assert _dc(got) == _dc(want), want.name
        assert _startup(got) == _startup(want), want.name
        assert got.modes.loop == want.modes.loop and got.modes.set_by == want.modes.set_by


def test_two_drives_claiming_one_alias_are_refused_in_one_line() -> None:
    with pytest.raises(ScanError) as err:
        check_unique([(0, "slave 1"), (7, "slave 2"), (0, "slave 3"), (7, "slave 4")], "alias")
    assert str(err.value).startswith("slave 2 and slave 4 both claim alias 7")
    check_unique([(0, "slave 1"), (0, "slave 2"), (3, "slave 3")], "alias")  # 0: no claim


def _set_alias(iface: str, positions: list[int], alias: int) -> None:
    """Write station alias ``alias`` into the SII (word 4, checksum word 7) of the slaves at
    ``positions`` (0-based), as ``ethercat alias`` does on a real bus."""
    import struct

    import pysoem

    from drivers.sim.esc.sii import crc8

    m = pysoem.Master()
    m.open(iface)
    try:
        assert m.config_init() > max(positions)
        for pos in positions:
            s = m.slaves[pos]
            s.eeprom_write(4, struct.pack("<H", alias))
            header = b"".join(bytes(s.eeprom_read(w))[:4] for w in (0, 2, 4, 6))[:14]
            s.eeprom_write(7, struct.pack("<H", crc8(header)))
            assert struct.unpack("<H", bytes(s.eeprom_read(4))[:2])[0] == alias
    finally:
        m.close()


@pytest.mark.root
def test_a_bus_where_two_drives_claim_one_station_alias_is_refused_end_to_end(
    tmp_path: Path, capsys
) -> None:
    config = write_mixed_config(tmp_path)
    out = tmp_path / "scanned"
    with (
        veth_pair("am", "as") as (master, slave),
        emulator(sim_ethercat_args(slave, config), tmp_path, timeout=30.0),
    ):
        _set_alias(master, [1, 3], 7)
        code = main(["bus", "scan", "--iface", master, "-o", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert "\n" not in err and "Traceback" not in err
    assert "slave 2 (" in err and "slave 4 (" in err and "both claim station alias 7" in err
    assert not out.exists()  # nothing written


def test_scan_reads_each_object_as_its_own_after_a_late_answer() -> None:
    """``bus scan`` reads CoE with SOEM too: 0x1018:01 answered late twice (the retry would
    take the first late answer and leave its own for 0x1018:02). The mailbox is brought
    back in step before the next read, so the product code is the product code."""
    import pysoem
    from support.soem_mailbox import MailboxSlave

    from drivers.ethercat.scan import _read_slave

    values = {(0x1018, 1): 0x00000A5F, (0x1018, 2): 0x00402001, (0x1018, 3): 7}
    values |= {(0x1000, 0): 0x00020192, (0x1C00, 0): 4, (0x1C12, 0): 0, (0x1C13, 0): 0}
    slave = MailboxSlave(values, late=[(0x1018, 1), (0x1018, 1)])
    drive = _read_slave(0, slave, pysoem)
    assert (drive.vendor_id, drive.product_code, drive.revision) == (0x00000A5F, 0x00402001, 7)
    assert slave.pending == [] and slave.held == []
