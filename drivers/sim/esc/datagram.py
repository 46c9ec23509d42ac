"""EtherCAT frames through a line of emulated slaves: every datagram command, with its WKC.

A frame is processed in place in a ``bytearray``: Ethernet header (14 bytes), EtherCAT
header (length u16 with type 1 in bits 12-15), then datagrams of ``cmd u8, idx u8,
address u32, len u16 (bits 0-10 length, bit 15 more datagrams follow), irq u16, data, wkc
u16``. Each slave on the line processes each datagram in turn, as the frame passes it.

Working counter (ETG.1000.4): +1 per slave that performs a read, +1 per write, +3 for a
read-write (1 + 2); LRW adds 1 per read-FMMU hit and 2 per write-FMMU hit; BRD/BWR add 1
per slave; ARMW/FRMW add 1 for the reading slave and 1 per writing slave.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

from drivers.sim.esc.esc import Esc

ETH_HEADER = 14
ETHERTYPE_ECAT = 0x88A4
DG_HEADER = 10

NOP, APRD, APWR, APRW, FPRD, FPWR, FPRW, BRD, BWR, BRW, LRD, LWR, LRW, ARMW, FRMW = range(15)
COMMAND_NAMES = "NOP APRD APWR APRW FPRD FPWR FPRW BRD BWR BRW LRD LWR LRW ARMW FRMW".split()

_hdr = struct.Struct("<BBHHHH")
_u16 = struct.Struct("<H")


def process_frame(
    frame: bytearray, length: int, slaves: Sequence[Esc], cut_at: int | None = None
) -> bool:
    """Run every datagram of ``frame[:length]`` through ``slaves`` (in line order).

    Slaves with ``silent`` set do not process (nor count positions). ``cut_at``: slaves
    from that position on see a damaged frame (CRC error) and do not process it; their
    receive error counter (0x0300) is incremented. Returns True when the frame carried a
    logical (process-data) datagram. Raises ``ValueError`` on a malformed frame.
    """
    if length < ETH_HEADER + 2 + DG_HEADER + 2:
        raise ValueError(f"frame of {length} bytes is too short for EtherCAT")
    ecat = _u16.unpack_from(frame, ETH_HEADER)[0]
    if ecat >> 12 != 1:
        raise ValueError(f"EtherCAT header type {ecat >> 12} is not 1 (datagrams)")
    end = ETH_HEADER + 2 + (ecat & 0x07FF)
    if end > length:
        raise ValueError(f"EtherCAT length {ecat & 0x7FF} runs past the frame ({length} bytes)")
    live = [s for s in slaves if not s.silent]
    if cut_at is not None:
        for s in slaves[cut_at:]:
            s.mem[0x0300] = min(s.mem[0x0300] + 1, 0xFF)  # port 0 invalid frame counter
        live = [s for s in live if s.position < cut_at]
    pos = ETH_HEADER + 2
    logical = False
    view = memoryview(frame)
    while pos + DG_HEADER + 2 <= end:
        cmd, _idx, adp, ado, dlen, _irq = _hdr.unpack_from(frame, pos)
        size = dlen & 0x07FF
        data = pos + DG_HEADER
        wkc_at = data + size
        if wkc_at + 2 > end:
            raise ValueError(f"datagram at byte {pos} runs past the EtherCAT length")
        wkc = _u16.unpack_from(frame, wkc_at)[0]
        if cmd in (LRD, LWR, LRW):
            logical = True
            laddr = adp | (ado << 16)
            for s in live:
                wkc += s.logical(cmd, laddr, frame, data, size)
        elif cmd in (FPRD, FPWR, FPRW, FRMW):
            wkc += _configured(cmd, adp, ado, frame, data, size, live, view)
        elif cmd in (APRD, APWR, APRW, ARMW):
            wkc += _auto_increment(cmd, adp, ado, frame, data, size, live, view)
            _u16.pack_into(frame, pos + 2, (adp + len(live)) & 0xFFFF)
        elif cmd in (BRD, BWR, BRW):
            wkc += _broadcast(cmd, ado, frame, data, size, live, view)
            _u16.pack_into(frame, pos + 2, (adp + len(live)) & 0xFFFF)
        _u16.pack_into(frame, wkc_at, wkc & 0xFFFF)
        pos = wkc_at + 2
        if not dlen & 0x8000:
            break
    return logical


def _rw(s: Esc, ado: int, frame: bytearray, data: int, size: int, view: memoryview) -> int:
    old = bytes(view[data : data + size])
    got = s.read(ado, frame, data, size)
    put = s.write(ado, old)
    return int(got) + 2 * int(put)


def _configured(
    cmd: int,
    adp: int,
    ado: int,
    frame: bytearray,
    data: int,
    size: int,
    live: list[Esc],
    view: memoryview,
) -> int:
    if cmd == FRMW:
        wkc = 0
        source = None
        for s in live:
            if s.station_address == adp and source is None:
                source = s
                wkc += s.read(ado, frame, data, size)
            elif source is not None:
                wkc += s.write(ado, bytes(view[data : data + size]))
        return wkc
    for s in live:
        if s.station_address == adp:
            if cmd == FPRD:
                return int(s.read(ado, frame, data, size))
            if cmd == FPWR:
                return int(s.write(ado, view[data : data + size]))
            return _rw(s, ado, frame, data, size, view)
    return 0


def _auto_increment(
    cmd: int,
    adp: int,
    ado: int,
    frame: bytearray,
    data: int,
    size: int,
    live: list[Esc],
    view: memoryview,
) -> int:
    wkc = 0
    source = None
    for k, s in enumerate(live):
        addressed = (adp + k) & 0xFFFF == 0
        if cmd == ARMW:
            if addressed:
                source = s
                wkc += s.read(ado, frame, data, size)
            elif source is not None:
                wkc += s.write(ado, bytes(view[data : data + size]))
            continue
        if not addressed:
            continue
        if cmd == APRD:
            wkc += s.read(ado, frame, data, size)
        elif cmd == APWR:
            wkc += s.write(ado, view[data : data + size])
        else:
            wkc += _rw(s, ado, frame, data, size, view)
    return wkc


def _broadcast(
    cmd: int,
    ado: int,
    frame: bytearray,
    data: int,
    size: int,
    live: list[Esc],
    view: memoryview,
) -> int:
    wkc = 0
    scratch = bytearray(size)
    for s in live:
        incoming = bytes(view[data : data + size])
        if cmd in (BRD, BRW) and s.read(ado, scratch, 0, size):
            wkc += 1
            # a broadcast read ORs every slave's data into the datagram
            merged = int.from_bytes(incoming, "little") | int.from_bytes(scratch, "little")
            frame[data : data + size] = merged.to_bytes(size, "little")
        if cmd in (BWR, BRW) and s.write(ado, incoming):
            wkc += 1 if cmd == BWR else 2
    return wkc


def describe_frame(frame: bytes) -> list[tuple[str, int, int, int, int]]:
    """Datagrams of a frame as (command name, adp, ado, length, wkc), for logs and tests."""
    out = []
    ecat = _u16.unpack_from(frame, ETH_HEADER)[0]
    end = ETH_HEADER + 2 + (ecat & 0x07FF)
    pos = ETH_HEADER + 2
    while pos + DG_HEADER + 2 <= end:
        cmd, _idx, adp, ado, dlen, _irq = _hdr.unpack_from(frame, pos)
        size = dlen & 0x07FF
        wkc = _u16.unpack_from(frame, pos + DG_HEADER + size)[0]
        name = COMMAND_NAMES[cmd] if cmd < len(COMMAND_NAMES) else f"cmd{cmd}"
        out.append((name, adp, ado, size, wkc))
        pos += DG_HEADER + size + 2
        if not dlen & 0x8000:
            break
    return out
