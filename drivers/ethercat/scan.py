"""Read a live EtherCAT bus into :class:`~drivers.cia402.scan.ScannedDrive` records.

SOEM scans the line (SII identity and name); each slave goes to PRE-OP and is read by CoE
SDO: 0x1018, the assignment 0x1C12/0x1C13 and every assigned mapping, 0x6502, which CiA-402
objects exist, the units objects; the SII's DC category (ETG.2010 type 60) gives the DC op
mode (AssignActivate, SYNC0 cycle and shift). Fixed and configurable PDOs are told apart by
writing each assigned mapping's entry count back unchanged in PRE-OP and reading it back (a
fixed mapping aborts the write; a configurable one takes it as a no-op): that and the AL state
are all a scan writes. (CoE SDO Information would say the same through the entries' access
rights, but drives answer it unevenly and the emulator does not implement it.) Two slaves with
one station alias (SII word 4) are refused.
"""

from __future__ import annotations

import os
import struct
import time
from typing import Any

from drivers.cia402.pdo import RXPDO_ASSIGN_INDEX, TXPDO_ASSIGN_INDEX
from drivers.cia402.scan import PROBED_OBJECTS, ScanError, ScannedDrive, ScannedPdo, check_unique
from drivers.ethercat.al_status import STATE_PREOP
from drivers.ethercat.mailbox import resync

_CAT_DC = 60
_CAT_END = 0xFFFF
_SII_CATEGORIES = 0x40
_SII_ALIAS = 0x04


def _sii_words(slave: Any, word: int, count: int) -> bytes:
    out = bytearray()
    while len(out) < 2 * count:
        out += bytes(slave.eeprom_read(word + len(out) // 2))[:4]
    return bytes(out[: 2 * count])


def sii_dc(slave: Any) -> dict[str, int] | None:
    """The first DC op mode of the SII's DC category, or None when there is none."""
    word = _SII_CATEGORIES
    for _ in range(64):  # categories
        cat, length = struct.unpack("<HH", _sii_words(slave, word, 2))
        if cat == _CAT_END or cat == 0:
            return None
        if cat == _CAT_DC and length * 2 >= 24:
            data = _sii_words(slave, word + 2, 12)
            cycle, shift0, _shift1, _f1, assign, _f0, _n, _d = struct.unpack("<IIIhHhBB", data[:20])
            return {"assign_activate": assign, "sync0_cycle_ns": cycle, "sync0_shift_ns": shift0}
        word += 2 + length
    return None


def scan(iface: str, timeout: float = 5.0) -> list[ScannedDrive]:
    """Every slave on ``iface``; ScanError (one line) when the bus cannot be read."""
    import pysoem

    if not os.path.exists(f"/sys/class/net/{iface}"):
        raise ScanError(f"--iface: network interface {iface!r} does not exist (see `ip link`)")
    m = pysoem.Master()
    try:
        m.open(iface)
    except ConnectionError:
        raise ScanError(f"cannot open {iface!r}: raw sockets need root or CAP_NET_RAW") from None
    try:
        deadline = time.monotonic() + timeout
        found = m.config_init()
        while (found <= 0 or any(s.man == 0 for s in m.slaves)) and time.monotonic() < deadline:
            time.sleep(0.01)
            found = m.config_init()
        if found <= 0:
            raise ScanError(f"no EtherCAT slave answered on {iface}")
        slaves = list(m.slaves)
        who = [f"slave {i + 1} ('{s.name}')" for i, s in enumerate(slaves)]
        aliases = [struct.unpack("<H", _sii_words(s, _SII_ALIAS, 1))[0] for s in slaves]
        check_unique(list(zip(aliases, who, strict=True)), "station alias")
        m.state = STATE_PREOP
        m.write_state()
        if m.state_check(STATE_PREOP, 3_000_000) != STATE_PREOP:
            raise ScanError(f"{iface}: the slaves did not reach PRE-OP for the CoE reads")
        return [_read_slave(i, s, pysoem) for i, s in enumerate(slaves)]
    finally:
        try:
            m.state = 1
            m.write_state()
        except Exception:  # the bus is being left: nothing more to do
            pass
        m.close()


def _read_slave(i: int, s: Any, pysoem: Any) -> ScannedDrive:
    address = f"slave {i + 1}"

    transient = (pysoem.WkcError, pysoem.MailboxError, pysoem.PacketError)
    # the object of the last transfer that got no valid answer (None: in step); the mailbox
    # is brought back in step before the next transfer, fenced off that object (as the master)
    failed: list[int | None] = [None]

    def transfer(call: Any, index: int, what: str) -> Any:
        """``call()`` with retries; an SdoError (the drive's answer) propagates. After a
        transfer that got no valid answer the mailbox is brought back in step before the
        next (its late answer must not be taken for another: drivers.ethercat.mailbox)."""
        for _attempt in range(4):
            if failed[0] is not None:
                if resync(s.sdo_read, transient + (pysoem.SdoError,), failed[0]) is None:
                    time.sleep(0.01)
                    continue
                failed[0] = None
            try:
                return call()
            except transient:
                failed[0] = index
                time.sleep(0.01)
        raise ScanError(f"{address} ('{s.name}'): {what} got no answer")

    def read(index: int, sub: int, size: int) -> int | None:
        try:
            data = bytes(
                transfer(lambda: s.sdo_read(index, sub), index, f"SDO read 0x{index:04X}:{sub:02X}")
            )
        except pysoem.SdoError:
            return None
        return int.from_bytes(data[:size].ljust(size, b"\0"), "little")

    def pdos(assign: int) -> list[ScannedPdo]:
        count = read(assign, 0, 1) or 0
        out = []
        for k in range(1, count + 1):
            index = read(assign, k, 2) or 0
            n = read(index, 0, 1) or 0
            entries = []
            for e in range(1, n + 1):
                raw = read(index, e, 4) or 0
                entries.append((raw >> 16, (raw >> 8) & 0xFF, raw & 0xFF))
            out.append(ScannedPdo(index, entries, fixed=not writable(index, n)))
        return out

    def writable(index: int, count: int) -> bool:
        """Whether mapping object ``index`` is configurable: its entry count written back
        unchanged in PRE-OP (a no-op for a configurable PDO) and read back. A fixed PDO
        aborts the write (0x06010002 read-only, or another abort code)."""
        try:
            transfer(
                lambda: s.sdo_write(index, 0, bytes([count])), index, f"SDO write 0x{index:04X}:00"
            )
        except pysoem.SdoError:
            return False
        return read(index, 0, 1) == count

    ident = [read(0x1018, k, 4) for k in (1, 2, 3)]
    d = ScannedDrive(
        bus="ethercat",
        address=address,
        name=str(s.name),
        vendor_id=ident[0] if ident[0] is not None else int(s.man),
        product_code=ident[1] if ident[1] is not None else int(s.id),
        revision=ident[2] if ident[2] is not None else int(s.rev),
        rx_pdos=pdos(RXPDO_ASSIGN_INDEX),
        tx_pdos=pdos(TXPDO_ASSIGN_INDEX),
        dc=sii_dc(s),
    )
    for index in PROBED_OBJECTS:
        sub = 1 if index == 0x60C2 else 0
        if read(index, sub, 1) is not None:
            d.objects.add(index)
    d.supported_modes = read(0x6502, 0, 4)
    for index in (0x608F, 0x6091, 0x6092):
        a, b = read(index, 1, 4), read(index, 2, 4)
        if a is not None and b is not None:
            d.units[index] = (a, b)
    return d
