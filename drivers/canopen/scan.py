"""Read a live CANopen bus into :class:`~drivers.cia402.scan.ScannedDrive` records.

NMT reset communication makes every node send its boot-up message: the nodes that answer
are the bus (two boot-ups from one node id are two drives claiming it: refused in one line).
Each node is then read by SDO through the ``canopen`` library: 0x1018, the RPDO/TPDO
communication parameters 0x1400../0x1800.. (COB-ID, enabled, transmission type) and
mappings 0x1600../0x1A00.. up to the first missing one, how many entries a mapping takes,
0x6502, which CiA-402 objects exist, the units objects.

Fixed or configurable, probed the CiA 301 way while the nodes are PRE-OPERATIONAL (after the
reset): per PDO, the PDO is made invalid (COB-ID bit 31 set), the mapping's entry count
(sub 0) written back unchanged and read back, then the COB-ID restored exactly as it was. A
configurable mapping takes the write (a no-op); a fixed one aborts it (0x06010002 read only,
or another code: 0x06090030, 0x08000020 ...). A node that refuses to make the PDO invalid
cannot be remapped either: fixed too. Nothing else is written but NMT, and every probe
leaves the node as it found it (a COB-ID that cannot be restored is refused in one line).
"""

from __future__ import annotations

import time
from collections import Counter
from typing import Any

from drivers.canopen import layout
from drivers.cia402.scan import PROBED_OBJECTS, ScanError, ScannedDrive, ScannedPdo


def scan(
    interface: str,
    channel: str,
    bitrate: int = 1_000_000,
    boot_wait: float = 1.0,
    sdo_timeout: float = 1.0,
) -> list[ScannedDrive]:
    """Every node on ``channel``; ScanError (one line) when the bus cannot be read."""
    import can
    import canopen

    kw: dict[str, Any] = {} if interface in ("virtual", "udp_multicast") else {"bitrate": bitrate}
    try:
        setup = can.Bus(interface=interface, channel=channel, **kw)
        listen = can.Bus(interface=interface, channel=channel, **kw)
    except (can.CanError, OSError, ValueError, ImportError) as exc:
        raise ScanError(f"cannot open CAN channel {channel!r} ({interface}): {exc}") from None
    net = canopen.Network(setup)
    net.connect()
    try:
        while listen.recv(0.0) is not None:
            pass
        net.nmt.send_command(layout.NMT_RESET_COMM)
        boots: Counter[int] = Counter()
        end = time.monotonic() + boot_wait
        while time.monotonic() < end:
            m = listen.recv(0.05)
            if m is None or m.is_error_frame or m.is_remote_frame:
                continue
            nid = m.arbitration_id - layout.HEARTBEAT_BASE
            if 1 <= nid <= 127 and bytes(m.data[:1]) == bytes([layout.NMT_BOOTUP]):
                boots[nid] += 1
        if not boots:
            raise ScanError(
                f"CAN channel {channel}: no node sent a boot-up message within "
                f"{boot_wait:g} s of NMT reset communication"
            )
        twice = sorted(n for n, c in boots.items() if c > 1)
        if twice:
            raise ScanError(
                f"CAN channel {channel}: two drives claim node id {twice[0]} (two "
                "boot-up messages): give each drive its own before scanning"
            )
        out = []
        for nid in sorted(boots):
            node = canopen.RemoteNode(nid, canopen.ObjectDictionary())
            node.sdo.RESPONSE_TIMEOUT = sdo_timeout
            net.add_node(node)
            out.append(_read_node(node, nid, bitrate, canopen))
        return out
    finally:
        net.disconnect()
        listen.shutdown()


def _read_node(node: Any, nid: int, bitrate: int, canopen: Any) -> ScannedDrive:
    address = f"node {nid}"

    def read(index: int, sub: int, size: int) -> int | None:
        try:
            data = bytes(node.sdo.upload(index, sub))
        except canopen.SdoAbortedError:
            return None
        except canopen.SdoCommunicationError:
            raise ScanError(f"{address}: SDO read 0x{index:04X}:{sub:02X} got no answer") from None
        return int.from_bytes(data[:size].ljust(size, b"\0"), "little")

    def write(index: int, sub: int, value: int, size: int) -> bool:
        """SDO download; False when the node aborts it."""
        try:
            node.sdo.download(index, sub, value.to_bytes(size, "little"))
        except canopen.SdoAbortedError:
            return False
        except canopen.SdoCommunicationError:
            raise ScanError(f"{address}: SDO write 0x{index:04X}:{sub:02X} got no answer") from None
        return True

    def fixed(comm: int, mapping: int, cob: int, count: int) -> bool:
        """Whether ``mapping`` refuses a write (see the module docstring)."""
        if not cob & layout.COB_ID_INVALID and not write(comm, 1, cob | layout.COB_ID_INVALID, 4):
            return True  # the PDO cannot be made invalid: not remappable
        try:
            return not (write(mapping, 0, count, 1) and read(mapping, 0, 1) == count)
        finally:
            if not cob & layout.COB_ID_INVALID and not (
                write(comm, 1, cob, 4) and read(comm, 1, 4) == cob
            ):
                raise ScanError(
                    f"{address}: 0x{comm:04X}:01 (COB-ID) could not be restored to "
                    f"0x{cob:08X} after probing 0x{mapping:04X}: reset the node"
                )

    def pdos(comm_base: int, map_base: int) -> tuple[list[ScannedPdo], int]:
        out, max_entries = [], 0
        for k in range(512):
            cob = read(comm_base + k, 1, 4)
            if cob is None:
                break
            ttype = read(comm_base + k, 2, 1)
            n = read(map_base + k, 0, 1) or 0
            entries = []
            for e in range(1, n + 1):
                raw = read(map_base + k, e, 4) or 0
                entries.append((raw >> 16, (raw >> 8) & 0xFF, raw & 0xFF))
            subs = n
            while subs < 64 and read(map_base + k, subs + 1, 4) is not None:
                subs += 1
            max_entries = max(max_entries, subs)
            if entries:
                out.append(
                    ScannedPdo(
                        map_base + k,
                        entries,
                        (cob & 0x7FF) - nid,
                        1 if ttype is None else ttype,
                        not cob & layout.COB_ID_INVALID,
                        fixed=fixed(comm_base + k, map_base + k, cob, n),
                    )
                )
        return out, max_entries

    ident = [read(0x1018, k, 4) for k in (1, 2, 3)]
    name_raw = b""
    try:
        name_raw = bytes(node.sdo.upload(0x1008, 0))
    except (canopen.SdoAbortedError, canopen.SdoCommunicationError):
        pass
    rx, rx_max = pdos(0x1400, 0x1600)
    tx, tx_max = pdos(0x1800, 0x1A00)
    d = ScannedDrive(
        bus="canopen",
        address=address,
        name=name_raw.decode("ascii", "replace").strip("\0 ") or f"node {nid}",
        vendor_id=ident[0] or 0,
        product_code=ident[1] or 0,
        revision=ident[2] or 0,
        rx_pdos=rx,
        tx_pdos=tx,
        max_entries=max(rx_max, tx_max) or None,
        bitrate=bitrate,
    )
    for index in PROBED_OBJECTS:
        if read(index, 1 if index == 0x60C2 else 0, 1) is not None:
            d.objects.add(index)
    d.supported_modes = read(0x6502, 0, 4)
    for index in (0x608F, 0x6091, 0x6092):
        a, b = read(index, 1, 4), read(index, 2, 4)
        if a is not None and b is not None:
            d.units[index] = (a, b)
    return d
