"""Bad vendor files: one line naming the file and the problem, fast, nothing expanded or read
that the file points at."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from drivers.profiles import ProfileImportError, read_vendor_description
from drivers.profiles.choose import choose
from tests.support.esi_factory import entry, esi


def _write(tmp_path: Path, text: str | bytes, name: str = "drive.xml") -> Path:
    path = tmp_path / name
    path.write_bytes(text.encode() if isinstance(text, str) else text)
    return path


def _refused(path: Path) -> str:
    with pytest.raises(ProfileImportError) as err:
        choose(read_vendor_description(path)[0])
    msg = str(err.value)
    assert "\n" not in msg and str(path) in msg
    return msg


def test_factory_file_imports(tmp_path):
    p = choose(read_vendor_description(_write(tmp_path, esi()))[0]).profile
    assert p.identity.product_code == 0x1234 and p.modes.loop == "csp"
    assert p.rx_pdos[0].entries[-1].index == 0  # padding kept
    assert p.startup_value(0x60C2, 1) == "loop_period"


def test_decimal_numbers_and_bom(tmp_path):
    text = esi(number="dec")
    path = _write(tmp_path, b"\xef\xbb\xbf" + text.encode())
    p = choose(read_vendor_description(path)[0]).profile
    assert p.identity.vendor_id == 0x99 and p.rx_pdos[0].index == 0x1600
    assert p.rx_pdos[0].entries[0].field == "controlword"


def test_truncated_xml(tmp_path):
    text = esi()
    msg = _refused(_write(tmp_path, text[: len(text) // 2]))
    assert "not valid XML" in msg and "truncated" in msg


def test_not_xml_nor_ini(tmp_path):
    msg = _refused(_write(tmp_path, "hello, this is text\n", "drive.txt"))
    assert "neither XML (ESI) nor INI (EDS/DCF)" in msg


def test_binary(tmp_path):
    assert "binary" in _refused(_write(tmp_path, bytes(range(256)) * 4, "drive.bin"))


def test_wrong_root(tmp_path):
    assert "not <EtherCATInfo>" in _refused(_write(tmp_path, "<html><body/></html>"))


def test_entity_bomb_refused_fast(tmp_path):
    bomb = (
        '<?xml version="1.0"?>\n<!DOCTYPE lolz [\n<!ENTITY lol "lol">\n'
        + "".join(
            f'<!ENTITY lol{k} "{("&lol" + (str(k - 1) if k > 1 else "") + ";") * 10}">\n'
            for k in range(1, 10)
        )
        + "]>\n<EtherCATInfo><Vendor><Id>&lol9;</Id></Vendor></EtherCATInfo>\n"
    )
    import tracemalloc

    tracemalloc.start()
    t0 = time.perf_counter()
    msg = _refused(_write(tmp_path, bomb))
    elapsed = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert "DOCTYPE" in msg
    assert elapsed < 5.0 and peak < 20 << 20  # 10^9 'lol's would be gigabytes


def test_external_entity_not_read(tmp_path):
    secret = tmp_path / "secret.txt"
    secret.write_text("TOP-SECRET-CONTENT")
    text = (
        f'<?xml version="1.0"?>\n<!DOCTYPE x [<!ENTITY ext SYSTEM "file://{secret}">]>\n'
        "<EtherCATInfo><Vendor><Id>1</Id><Name>&ext;</Name></Vendor></EtherCATInfo>\n"
    )
    msg = _refused(_write(tmp_path, text))
    assert "DOCTYPE" in msg and "TOP-SECRET" not in msg


def test_overlapping_entries(tmp_path):
    rx = entry(0x6040, 16) + entry(0x607A, 32) + entry(0x6040, 16)
    msg = _refused(_write(tmp_path, esi(rx_entries=rx)))
    assert "maps 0x6040:00 twice (overlapping entries)" in msg


def test_pdo_exceeds_sync_manager(tmp_path):
    msg = _refused(_write(tmp_path, esi(sm_max=4)))
    assert "more than sync manager 2's MaxSize 4" in msg


def test_no_cyclic_mode(tmp_path):
    msg = _refused(_write(tmp_path, esi(modes="25000000")))  # pp, pv, hm
    assert "no cyclic synchronous mode (csp, csv, cst)" in msg and "pp, pv, hm" in msg


def test_loop_target_not_mappable(tmp_path):
    rx = entry(0x6040, 16) + entry(0x6071, 16)
    tx = entry(0x6041, 16) + entry(0x6064, 32)
    path = _write(tmp_path, esi(rx_entries=rx, tx_entries=tx))
    desc = read_vendor_description(path)[0]
    desc.objects.pop((0x607A, 0))  # not in the dictionary either
    with pytest.raises(ProfileImportError, match="cannot map target_position"):
        choose(desc, loop="csp")
    assert choose(desc).profile.modes.loop == "cst"  # the default falls back to what maps


def test_bad_number(tmp_path):
    text = esi().replace("<BitLen>16</BitLen>", "<BitLen>sixteen</BitLen>", 1)
    msg = _refused(_write(tmp_path, text))
    assert "not a number (got 'sixteen')" in msg


EDS = """[FileInfo]
FileName=test.eds
[DeviceInfo]
VendorName=Test
VendorNumber=0x99
ProductName=CanDrive
ProductNumber=7
RevisionNumber=0x10
BaudRate_500=1
BaudRate_1000=1
NrOfRXPDO=1
NrOfTXPDO=1
[1400]
SubNumber=3
[1400sub1]
DataType=0x0007
AccessType=rw
DefaultValue=$NODEID+0x80000200
[1400sub2]
DataType=0x0005
AccessType=rw
DefaultValue=255
[1600]
SubNumber=3
[1600sub0]
DataType=0x0005
AccessType=rw
DefaultValue=0
[1600sub1]
DataType=0x0007
AccessType=rw
DefaultValue=0
[1600sub2]
DataType=0x0007
AccessType=rw
DefaultValue=0
[1800]
SubNumber=3
[1800sub1]
DataType=0x0007
AccessType=rw
DefaultValue=$NODEID+0x180
[1800sub2]
DataType=0x0005
AccessType=rw
DefaultValue=1
[1A00]
SubNumber=3
[1A00sub0]
DataType=0x0005
AccessType=rw
DefaultValue=0
[1A00sub1]
DataType=0x0007
AccessType=rw
DefaultValue=0
[1A00sub2]
DataType=0x0007
AccessType=rw
DefaultValue=0
[6040]
DataType=0x0006
AccessType=rww
PDOMapping=1
[6041]
DataType=0x0006
AccessType=ro
PDOMapping=1
[6064]
DataType=0x0004
AccessType=ro
PDOMapping=1
[607A]
DataType=0x0004
AccessType=rww
PDOMapping=1
LowLimit=0x80000000
[6502]
DataType=0x0007
AccessType=ro
DefaultValue=0x00000080
"""


def test_small_eds(tmp_path):
    desc = read_vendor_description(_write(tmp_path, EDS, "d.eds"))[0]
    assert desc.bitrates == [500_000, 1_000_000] and desc.revision == 0x10
    c = choose(desc)
    p = c.profile
    assert p.canopen is not None and p.canopen.max_entries == 2
    assert p.canopen.rpdo[0].cob_id_base == 0x200 and not p.canopen.rpdo[0].enabled_by_default
    assert [e.field for e in p.rx_pdos[0].entries] == ["controlword", "target_position"]
    assert p.modes.set_by == "startup" and p.startup[0].transition == "PO"
    assert "mode" in c.reasons[1] or any("mode" in r for r in c.reasons)


def test_eds_signed_hex_default(tmp_path):
    text = EDS.replace("[6502]", "[6071]\nDataType=0x0003\nAccessType=rww\nPDOMapping=1\n"
                       "DefaultValue=0xFC18\n[6502]")  # fmt: skip
    desc = read_vendor_description(_write(tmp_path, text, "d.eds"))[0]
    assert desc.default_of(0x6071) == -1000


@pytest.mark.parametrize(
    ("text", "expect"),
    [
        ("[DeviceInfo\nVendorName=x\n", "not an INI file"),
        ("[Other]\nA=1\n", "no [DeviceInfo] section"),
        ("[DeviceInfo]\nVendorNumber=0xZZ\n", "VendorNumber: not a number"),
    ],
)
def test_bad_eds(tmp_path, text, expect):
    path = _write(tmp_path, text, "d.eds")
    with pytest.raises(ProfileImportError) as err:
        read_vendor_description(path)
    assert expect in str(err.value) and "\n" not in str(err.value)


def test_dcf_node_id_and_bom(tmp_path):
    text = "\ufeff" + EDS + "[DeviceComissioning]\nNodeID=0x05\nBaudrate=1000\n"
    desc = read_vendor_description(_write(tmp_path, text, "d.dcf"))[0]
    assert desc.node_id == 5
    p = choose(desc).profile
    assert p.canopen is not None and p.canopen.node_ids == (5, 5)


def test_initcmd_data_longer_than_the_object(tmp_path):
    text = esi().replace("<Data>01</Data>", "<Data>0100</Data>")  # 0x60C2:1 written as 2 bytes
    desc = read_vendor_description(_write(tmp_path, text))[0]
    desc.objects[(0x60C2, 1)] = type(desc.objects[(0x6040, 0)])(0x60C2, 1, 8)
    p = choose(desc).profile
    s = p.startup[0]
    assert (s.index, s.subindex, s.bits) == (0x60C2, 1, 8)


@pytest.mark.parametrize("data", ["#x", "0xZZ", "ABC"])
def test_bad_initcmd_data(tmp_path, data):
    msg = _refused(_write(tmp_path, esi().replace("<Data>01</Data>", f"<Data>{data}</Data>")))
    assert "not hex data" in msg


def test_mandatory_pdo_always_assigned(tmp_path):
    """A Mandatory fixed PDO stays assigned beside what is chosen; its objects are not mapped
    again."""
    text = esi().replace('<TxPdo Fixed="1" Sm="3">', '<TxPdo Fixed="1" Sm="3" Mandatory="1">')
    extra = (
        '<TxPdo Fixed="1"><Index>#x1A01</Index><Name>more</Name>'
        + "".join(f"<Entry><Index>#x{i:04X}</Index><SubIndex>0</SubIndex><BitLen>{b}</BitLen>"
                  "<Name>x</Name></Entry>" for i, b in ((0x6041, 16), (0x6064, 32), (0x606C, 32),
                                                        (0x6077, 16), (0x603F, 16)))
        + "</TxPdo>"
    )  # fmt: skip
    text = text.replace("<Mailbox>", extra + "<Mailbox>")
    p = choose(read_vendor_description(_write(tmp_path, text))[0]).profile
    assert [pdo.index for pdo in p.tx_pdos] == [0x1A00]  # 0x1A01 would map 0x6041 twice


def test_dcf_cob_id_with_node_id_included(tmp_path):
    text = EDS.replace("DefaultValue=$NODEID+0x180", "DefaultValue=0x185") + (
        "[DeviceComissioning]\nNodeID=5\n"
    )
    p = choose(read_vendor_description(_write(tmp_path, text, "d.dcf"))[0]).profile
    assert p.canopen is not None and p.canopen.tpdo[0].cob_id_base == 0x180


def test_pdo_assign_false_keeps_the_default_assignment(tmp_path):
    """ETG.2000: without PdoAssign the assignment cannot change: a better non-default PDO is
    not used; without PdoConfig nothing is written."""
    extra = (
        '<TxPdo Fixed="1"><Index>#x1A01</Index><Name>more</Name>'
        + "".join(f"<Entry><Index>#x{i:04X}</Index><SubIndex>0</SubIndex><BitLen>{b}</BitLen>"
                  "<Name>x</Name></Entry>" for i, b in ((0x6041, 16), (0x6064, 32), (0x606C, 32),
                                                        (0x6077, 16), (0x603F, 16)))
        + "</TxPdo>"
    )  # fmt: skip
    for coe, expect in (('PdoAssign="1" PdoConfig="1"', [0x1A01]), ("", [0x1A00])):
        text = esi(coe=coe).replace("<Mailbox>", extra + "<Mailbox>")
        c = choose(read_vendor_description(_write(tmp_path, text))[0])
        assert [pdo.index for pdo in c.profile.tx_pdos] == expect, coe
    assert any("PdoAssign=0" in r for r in c.reasons)
