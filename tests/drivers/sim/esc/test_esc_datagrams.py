"""Frames through a line of emulated slaves: addressing modes and working counters, and an
independent decode of the replies with scapy.contrib.ethercat."""

from __future__ import annotations

import struct

import pytest
from esc_helpers import make_desc, make_od

from drivers.sim.esc import datagram as dg
from drivers.sim.esc import registers as r
from drivers.sim.esc.esc import Esc


def _line(n: int = 6) -> list[Esc]:
    return [Esc(make_desc(), make_od(), i, n) for i in range(n)]


def _frame(*datagrams: tuple[int, int, int, bytes]) -> bytearray:
    body = b""
    for k, (cmd, adp, ado, data) in enumerate(datagrams):
        more = 0x8000 if k < len(datagrams) - 1 else 0
        body += struct.pack("<BBHHHH", cmd, k, adp, ado, len(data) | more, 0) + data + b"\0\0"
    eth = b"\xff" * 6 + b"\x01" * 6 + struct.pack("!H", 0x88A4)
    return bytearray(eth + struct.pack("<H", len(body) | 0x1000) + body)


def _run(slaves: list[Esc], frame: bytearray) -> list[tuple[str, int, int, int, int]]:
    dg.process_frame(frame, len(frame), slaves)
    return dg.describe_frame(bytes(frame))


def test_broadcast_read_counts_every_slave_and_auto_increment_addresses_one() -> None:
    line = _line()
    out = _run(line, _frame((dg.BRD, 0, r.TYPE, bytes(2))))
    assert out[0][4] == 6
    frame = _frame((dg.APWR, (-2) & 0xFFFF, r.STATION_ADDRESS, struct.pack("<H", 0x1003)))
    out = _run(line, frame)
    assert out[0][4] == 1
    assert out[0][1] == 4, "each slave increments ADP"
    assert [s.station_address for s in line] == [0, 0, 0x1003, 0, 0, 0]


def test_configured_address_read_write_and_rw() -> None:
    line = _line(3)
    line[1].write(r.STATION_ADDRESS, struct.pack("<H", 0x1002))
    frame = _frame(
        (dg.FPRD, 0x1002, r.AL_STATUS, bytes(2)),
        (dg.FPRD, 0x7777, r.AL_STATUS, bytes(2)),
        (dg.FPRW, 0x1002, 0x0200, b"\x55\x00"),
    )
    out = _run(line, frame)
    assert [d[4] for d in out] == [1, 0, 3]
    assert line[1].mem[0x0200] == 0x55


def test_silent_slave_and_damaged_frame_lower_the_wkc() -> None:
    line = _line()
    line[2].silent = True
    assert _run(line, _frame((dg.BRD, 0, r.TYPE, bytes(2))))[0][4] == 5
    line[2].silent = False
    frame = _frame((dg.BRD, 0, r.TYPE, bytes(2)))
    dg.process_frame(frame, len(frame), line, cut_at=4)
    assert dg.describe_frame(bytes(frame))[0][4] == 4
    assert line[4].mem[r.RX_ERROR_COUNTERS] == 1


def test_frmw_reference_clock_read_by_one_written_by_the_others() -> None:
    line = _line(4)
    for k, s in enumerate(line):
        s.write(r.STATION_ADDRESS, struct.pack("<H", 0x1001 + k))
    out = _run(line, _frame((dg.FRMW, 0x1001, r.DC_SYSTEM_TIME, bytes(8))))
    assert out[0][4] == 4  # 1 read + 3 writes


def test_malformed_frames_are_rejected() -> None:
    frame = _frame((dg.BRD, 0, 0, bytes(2)))
    struct.pack_into("<H", frame, 14, 0x1000 | 200)  # length beyond the frame
    with pytest.raises(ValueError, match="runs past"):
        dg.process_frame(frame, len(frame), _line(1))


def test_scapy_decodes_our_replies() -> None:
    """An independent decoder (scapy.contrib.ethercat) reads the emulator's reply frame."""
    scapy_all = pytest.importorskip("scapy.all", reason="scapy (dev extra) not installed")
    ecat = pytest.importorskip("scapy.contrib.ethercat")
    line = _line()
    for k, s in enumerate(line):
        s.write(r.STATION_ADDRESS, struct.pack("<H", 0x1001 + k))
    frame = _frame((dg.BRD, 0, r.TYPE, bytes(2)), (dg.FPRD, 0x1004, r.STATION_ADDRESS, bytes(2)))
    dg.process_frame(frame, len(frame), line)
    pkt = scapy_all.Ether(bytes(frame))
    brd = pkt[ecat.EtherCatBRD]
    fprd = pkt[ecat.EtherCatFPRD]
    assert brd.wkc == 6
    assert brd.adp == 6
    assert fprd.wkc == 1
    assert bytes(fprd.data) == struct.pack("<H", 0x1004)
