"""The CANopen PDO layout: how the shared CiA-402 process image travels in CAN frames.

The process image (:mod:`drivers.cia402.pdo`) is 15 bytes each way that matter per cycle,
more than one classic CAN frame (8 bytes) holds, so each drive gets two RPDOs and two
TPDOs. 0x603F (error code) and 0x60FD (digital inputs) do not travel cyclically: the error
code comes with the emergency message (EMCY) and is read by SDO on a fault.

RPDO1 0x1600 (COB-ID 0x200 + node): controlword, target position, torque offset (8 bytes)
RPDO2 0x1601 (COB-ID 0x300 + node): target velocity, target torque, modes of operation (7)
TPDO1 0x1A00 (COB-ID 0x180 + node): statusword, position actual, torque actual (8 bytes)
TPDO2 0x1A01 (COB-ID 0x280 + node): velocity actual, current actual, mode display (7)

Every PDO is synchronous: RPDOs received before a SYNC take effect at that SYNC, TPDOs are
sent on every SYNC (transmission type 1). Each PDO has a byte-copy plan between its frame
payload and the process-image record (:func:`copy_plan`).

Multi-axis nodes (CiA 402-1: axis k's objects at 0x6000 + 0x800·k): one node, one NMT state,
one heartbeat, one SDO server, one EMCY COB-ID; the PDOs of all its axes are numbered
consecutively (axis 0's first), PDO n in 0x1400/0x1600 + n - 1 (RPDO) and 0x1800/0x1A00 +
n - 1 (TPDO). CiA 301's predefined connection set gives COB-IDs to PDOs 1-4 only; the rule
for more (:func:`pdo_cob_base`): PDO n >= 5 takes the default COB-ID of PDO ((n - 1) mod 4)
+ 1 of node id + 64·((n - 1) // 4), i.e. base + 0x40·((n - 1) // 4), so up to 8 RPDOs and
8 TPDOs per node, and a node with more than 4 must have a node id <= 63 and borrows the
PDO COB-IDs of node id + 64, which must then not be on the bus. :func:`cob_id_clashes`
checks a whole bus: every PDO COB-ID against every other, against NMT, SYNC, EMCY
(0x80 + node), SDO (0x580/0x600 + node) and heartbeat (0x700 + node).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np

from drivers.cia402.pdo import OBJECT_FIELDS, RXPDO_DTYPE, TXPDO_DTYPE, PdoEntry

SYNC_COB_ID = 0x080
EMCY_BASE = 0x080
NMT_COB_ID = 0x000
SDO_TX_BASE = 0x580  # server -> client (answers)
SDO_RX_BASE = 0x600  # client -> server (requests)
HEARTBEAT_BASE = 0x700
#: CiA 301 NMT states as reported in heartbeats / boot-up
NMT_BOOTUP, NMT_STOPPED, NMT_OPERATIONAL, NMT_PRE_OPERATIONAL = 0x00, 0x04, 0x05, 0x7F
NMT_STATE_NAMES = {
    NMT_BOOTUP: "boot-up",
    NMT_STOPPED: "stopped",
    NMT_OPERATIONAL: "operational",
    NMT_PRE_OPERATIONAL: "pre-operational",
}
#: NMT command specifiers
NMT_START, NMT_STOP, NMT_ENTER_PRE_OP, NMT_RESET_NODE, NMT_RESET_COMM = 0x01, 0x02, 0x80, 0x81, 0x82
#: NMT command by name
NMT_COMMANDS = {
    "start": NMT_START,
    "stop": NMT_STOP,
    "pre-operational": NMT_ENTER_PRE_OP,
    "reset node": NMT_RESET_NODE,
    "reset communication": NMT_RESET_COMM,
}
#: transmission type: synchronous, every SYNC
SYNC_EVERY = 1
COB_ID_INVALID = 0x80000000


#: CiA 301 default COB-ID bases of PDOs 1-4 (+ node id)
RPDO_DEFAULT_BASES = (0x200, 0x300, 0x400, 0x500)
TPDO_DEFAULT_BASES = (0x180, 0x280, 0x380, 0x480)
#: PDOs per direction and node the borrowing rule gives COB-IDs to (see the module docstring)
MAX_PDOS_BY_RULE = 8


def pdo_cob_base(kind: str, number: int) -> int:
    """COB-ID base (COB-ID = base + node id) of PDO ``number`` (1-based) of ``kind`` ('rpdo'
    or 'tpdo'): CiA 301's default for 1-4, for 5-8 that of PDO ((n - 1) mod 4) + 1 + 0x40
    (the PDO COB-IDs of node id + 64; the node id must then be <= 63). Raises ValueError
    past 8."""
    if not 1 <= number <= MAX_PDOS_BY_RULE:
        raise ValueError(
            f"{kind.upper()}{number}: the COB-ID rule covers PDOs 1..{MAX_PDOS_BY_RULE} per node"
        )
    bases = RPDO_DEFAULT_BASES if kind == "rpdo" else TPDO_DEFAULT_BASES
    return bases[(number - 1) % 4] + 0x40 * ((number - 1) // 4)


def cob_id_clashes(nodes: list[tuple[int, str, list[tuple[str, int]]]]) -> list[str]:
    """Every COB-ID used twice on a bus, one line each. ``nodes``: per node (node id, who,
    [(PDO name, COB-ID), ...]). The node's EMCY, SDO and heartbeat COB-IDs and NMT / SYNC
    are added here."""
    users: dict[int, str] = {NMT_COB_ID: "NMT", SYNC_COB_ID: "SYNC"}
    out = []
    for nid, who, pdos in nodes:
        own = [
            ("EMCY", EMCY_BASE + nid),
            ("SDO answer", SDO_TX_BASE + nid),
            ("SDO request", SDO_RX_BASE + nid),
            ("heartbeat", HEARTBEAT_BASE + nid),
        ]
        for what, cob in own + list(pdos):
            name = f"{who} {what}"
            if not 0 < cob <= 0x7FF:
                out.append(f"{name}: COB-ID 0x{cob:03X} is not an 11-bit CAN identifier")
            elif cob in users:
                out.append(f"{name}: COB-ID 0x{cob:03X} is already {users[cob]}'s")
            else:
                users[cob] = name
    return out


def profile_pdo_cob_bases(profile: Any) -> list[tuple[str, int]]:
    """(PDO name, COB-ID base) of every PDO a CANopen ``profile`` runs (COB-ID = base + node
    id), e.g. ('TPDO3', 0x380)."""
    out = []
    for pdos, comms, kind in (
        (profile.rx_pdos, profile.canopen.rpdo, "RPDO"),
        (profile.tx_pdos, profile.canopen.tpdo, "TPDO"),
    ):
        for p, c in zip(pdos, comms, strict=True):
            out.append((f"{kind}{(p.index & 0x1FF) + 1}", c.cob_id_base))
    return out


def bus_cob_id_clashes(bus: Any, profiles: Sequence[Any]) -> list[str]:
    """:func:`cob_id_clashes` of a :class:`hofto_hw.config.drives.BusConfig` (``transport:
    canopen``) whose drives run ``profiles`` (one per drive; None: the built-in layout):
    one node per device, node ids ``bus.canopen.node_ids`` or 1..n."""
    from drivers.cia402.profiles import builtin_profile
    from hofto_hw.config.drives import device_map

    serve = device_map(bus.drives)
    n = max(d for d, _k in serve) + 1
    opts = getattr(bus, "canopen", None)
    ids = list(opts.node_ids) if opts is not None and opts.node_ids else list(range(1, n + 1))
    nodes = []
    for d, nid in enumerate(ids):
        first = [dev for dev, _k in serve].index(d)
        prof = profiles[first] if profiles[first] is not None else builtin_profile("canopen")
        names = ", ".join(f"bus.drives[{i}]" for i, (dev, _k) in enumerate(serve) if dev == d)
        pdos = [(name, base + nid) for name, base in profile_pdo_cob_bases(prof)]
        nodes.append((nid, f"node {nid} ({names})", pdos))
    return cob_id_clashes(nodes)


def _entry(index: int) -> PdoEntry:
    from drivers.cia402.pdo import OBJECT_TYPES

    bits = np.dtype(OBJECT_TYPES[(index, 0)]).itemsize * 8
    return PdoEntry(index, 0, bits, OBJECT_FIELDS[(index, 0)])


class CanPdo(NamedTuple):
    """One CANopen PDO: communication object, mapping object, COB-ID base, mapped objects."""

    name: str
    comm_index: int  # 0x1400+k (RPDO) / 0x1800+k (TPDO)
    map_index: int  # 0x1600+k / 0x1A00+k
    cob_base: int  # COB-ID = cob_base + node id
    entries: tuple[PdoEntry, ...]

    @property
    def size(self) -> int:
        """Payload size [byte]."""
        return sum(e.bit_length for e in self.entries) // 8


RPDOS: tuple[CanPdo, ...] = (
    CanPdo("RPDO1", 0x1400, 0x1600, 0x200, tuple(_entry(i) for i in (0x6040, 0x607A, 0x60B2))),
    CanPdo("RPDO2", 0x1401, 0x1601, 0x300, tuple(_entry(i) for i in (0x60FF, 0x6071, 0x6060))),
)
TPDOS: tuple[CanPdo, ...] = (
    CanPdo("TPDO1", 0x1800, 0x1A00, 0x180, tuple(_entry(i) for i in (0x6041, 0x6064, 0x6077))),
    CanPdo("TPDO2", 0x1801, 0x1A01, 0x280, tuple(_entry(i) for i in (0x606C, 0x6078, 0x6061))),
)

#: (payload offset, record offset, size) in bytes
CopyPlan = tuple[tuple[int, int, int], ...]


def copy_plan(entries: tuple[PdoEntry, ...] | list[PdoEntry], dtype: np.dtype) -> CopyPlan:
    """Byte-copy plan between a PDO payload mapping ``entries`` and a record of ``dtype``.

    Raises ``ValueError`` naming an object that is not a field of ``dtype``.
    """
    out = []
    off = 0
    for e in entries:
        if not e.field or e.field not in (dtype.names or ()):
            raise ValueError(f"object 0x{e.index:04X}:{e.subindex:02X} is not in this PDO")
        size = e.bit_length // 8
        out.append((off, dtype.fields[e.field][1], size))
        off += size
    return tuple(out)


RPDO_PLANS: tuple[CopyPlan, ...] = tuple(copy_plan(p.entries, RXPDO_DTYPE) for p in RPDOS)
TPDO_PLANS: tuple[CopyPlan, ...] = tuple(copy_plan(p.entries, TXPDO_DTYPE) for p in TPDOS)


def frame_payloads(n_nodes: int) -> list[int]:
    """Payload sizes [byte] of every frame of one cycle: SYNC, then each node's PDOs."""
    per_node = [p.size for p in RPDOS + TPDOS]
    return [0] + per_node * n_nodes
