"""A CiA 301 object dictionary for one emulated drive, served by every emulator.

The in-process SimBus, the EtherCAT emulator (CoE SDOs) and a CANopen emulator all call
:meth:`ObjectDictionary.read` / :meth:`ObjectDictionary.write` with raw bytes; errors are
:class:`SdoAbort` exceptions carrying the CiA 301 abort code to put in the abort frame.

Entries either hold their own value or are *bound* to one element of a live numpy array
(a process-image field view or a drive parameter array), so an SDO read of 0x6064 returns
the position the drive reports this cycle and an SDO write of 0x6072 changes the torque
limit the drive applies next cycle.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from drivers.canopen.layout import COB_ID_INVALID
from drivers.cia402 import codes
from drivers.cia402.codes import describe_sdo_abort
from drivers.cia402.pdo import (
    EXTRA_FIELDS,
    OBJECT_TYPES,
    RXPDO_ASSIGN_INDEX,
    RXPDO_INDEX,
    RXPDO_MAPPING,
    TXPDO_ASSIGN_INDEX,
    TXPDO_INDEX,
    TXPDO_MAPPING,
    PdoEntry,
    mapping_value,
    parse_mapping_value,
)

#: data type name -> (struct format, CiA 301 data type index)
KINDS: dict[str, tuple[str, int]] = {
    "bool": ("<B", 0x0001),
    "i8": ("<b", 0x0002),
    "i16": ("<h", 0x0003),
    "i32": ("<i", 0x0004),
    "u8": ("<B", 0x0005),
    "u16": ("<H", 0x0006),
    "u32": ("<I", 0x0007),
    "str": ("", 0x0009),  # VISIBLE_STRING
}

#: largest PDO the emulated drives accept [bits] (EtherCAT SM size limit in practice).
MAX_PDO_BITS = 64 * 8
MAX_PDO_ENTRIES = 16
#: CiA 301: a PDO's communication object is its mapping object's index minus this
_COMM_OF_MAPPING = 0x200


class SdoAbort(Exception):
    """Raised by the object dictionary; ``code`` is the CiA 301 abort code (u32)."""

    def __init__(self, code: int, index: int, subindex: int) -> None:
        self.code = code
        self.index = index
        self.subindex = subindex
        super().__init__(f"0x{index:04X}:{subindex:02X}: {describe_sdo_abort(code)}")


@dataclass
class OdEntry:
    """One sub-index. ``access``: ro, rw, wo, const. ``bound`` = (array, element)."""

    index: int
    subindex: int
    name: str
    kind: str
    access: str = "rw"
    value: int | bytes = 0
    pdo_mappable: bool = False
    low: int | None = None
    high: int | None = None
    bound: tuple[np.ndarray, int] | None = field(default=None, repr=False)

    @property
    def size(self) -> int:
        """Size in bytes (strings: current length)."""
        if self.kind == "str":
            return len(self.get_bytes())
        return struct.calcsize(KINDS[self.kind][0])

    def get(self) -> int:
        """Current integer value (not for strings)."""
        if self.bound is not None:
            arr, i = self.bound
            return int(arr[i])
        assert isinstance(self.value, int)
        return self.value

    def set(self, value: int) -> None:
        """Store an integer value without access checks (the device itself writing)."""
        if self.bound is not None:
            arr, i = self.bound
            arr[i] = value
        else:
            self.value = int(value)

    def get_bytes(self) -> bytes:
        """Current value as little-endian bytes."""
        if self.kind == "str":
            v = self.value
            return v if isinstance(v, bytes) else str(v).encode()
        return struct.pack(KINDS[self.kind][0], self.get())


class ObjectDictionary:
    """Objects of one device keyed by (index, subindex).

    ``pdo_locked`` is set by the emulator while PDOs run (EtherCAT SAFE-OP/OP, CANopen
    operational): PDO mapping and assignment objects then abort with 0x08000022.
    ``mapping_needs_invalid_pdo`` (a CANopen node, CiA 301): a mapping 0x16xx/0x1Axx takes a
    write only while its PDO is invalid (bit 31 of the COB-ID in 0x14xx/0x18xx:01); else
    it aborts 0x06090030, as CANopenNode does (its v1 stacks: 0x06010000).
    """

    def __init__(self, name: str = "drive") -> None:
        self.name = name
        self._entries: dict[tuple[int, int], OdEntry] = {}
        self._names: dict[int, str] = {}
        self.pdo_locked = False
        self.mapping_needs_invalid_pdo = False
        #: largest PDO accepted [bits]; a CANopen node sets 64 (one classic CAN frame)
        self.max_pdo_bits = MAX_PDO_BITS
        #: assignment object -> the PDO indices it accepts (a profile's drive: its own)
        self.assignable: dict[int, frozenset[int]] = {
            RXPDO_ASSIGN_INDEX: frozenset({RXPDO_INDEX}),
            TXPDO_ASSIGN_INDEX: frozenset({TXPDO_INDEX}),
        }

    # ------------------------------------------------------------------ building

    def add(self, entry: OdEntry, object_name: str | None = None) -> OdEntry:
        """Add one sub-index (``object_name`` names the whole index, for SDO info)."""
        if entry.kind not in KINDS:
            raise ValueError(f"unknown data type {entry.kind!r} for 0x{entry.index:04X}")
        self._entries[(entry.index, entry.subindex)] = entry
        self._names.setdefault(entry.index, object_name or entry.name)
        return entry

    def add_var(
        self, index: int, name: str, kind: str, access: str = "rw", value: int = 0, **kw: object
    ) -> OdEntry:
        """Add a single-value object at sub-index 0."""
        return self.add(OdEntry(index, 0, name, kind, access, value, **kw))  # type: ignore[arg-type]

    def add_record(
        self, index: int, name: str, subs: list[OdEntry], sub0_access: str = "ro"
    ) -> None:
        """Add a record/array: sub 0 (u8, highest sub-index) plus ``subs``."""
        self.add(OdEntry(index, 0, "number of entries", "u8", sub0_access, len(subs)), name)
        for e in subs:
            self.add(e, name)

    def remove(self, index: int) -> None:
        """Delete object ``index`` (every sub-index): the drive does not have it."""
        for key in [k for k in self._entries if k[0] == index]:
            del self._entries[key]
        self._names.pop(index, None)

    # ------------------------------------------------------------------- queries

    def __contains__(self, key: tuple[int, int]) -> bool:
        return key in self._entries

    def entry(self, index: int, subindex: int) -> OdEntry:
        """The entry at ``index:subindex``; raises SdoAbort like an SDO access would."""
        e = self._entries.get((index, subindex))
        if e is None:
            code = codes.ABORT_NO_SUBINDEX if index in self._names else codes.ABORT_NO_OBJECT
            raise SdoAbort(code, index, subindex)
        return e

    def indices(self) -> list[int]:
        """All object indices, sorted (SDO information: object list)."""
        return sorted(self._names)

    def object_name(self, index: int) -> str:
        """Name of object ``index``."""
        if index not in self._names:
            raise SdoAbort(codes.ABORT_NO_OBJECT, index, 0)
        return self._names[index]

    def subentries(self, index: int) -> list[OdEntry]:
        """Entries of ``index`` ordered by sub-index."""
        return sorted(
            (e for (i, _), e in self._entries.items() if i == index), key=lambda e: e.subindex
        )

    def __iter__(self) -> Iterator[OdEntry]:
        return iter(sorted(self._entries.values(), key=lambda e: (e.index, e.subindex)))

    def get(self, index: int, subindex: int = 0) -> int:
        """Integer value, no access checks (device side)."""
        return self.entry(index, subindex).get()

    def set(self, index: int, subindex: int, value: int) -> None:
        """Store an integer value, no access checks (device side)."""
        self.entry(index, subindex).set(value)

    # -------------------------------------------------------------- SDO services

    def read(self, index: int, subindex: int) -> bytes:
        """SDO upload: the value as little-endian bytes; raises SdoAbort."""
        e = self.entry(index, subindex)
        if e.access == "wo":
            raise SdoAbort(codes.ABORT_WRITE_ONLY, index, subindex)
        return e.get_bytes()

    def read_complete(self, index: int) -> bytes:
        """Complete-access upload (EtherCAT CoE): sub 0 padded to 16 bits, then subs 1..n."""
        subs = self.subentries(index)
        if not subs:
            raise SdoAbort(codes.ABORT_NO_OBJECT, index, 0)
        out = bytearray()
        for e in subs:
            data = self.read(index, e.subindex)
            out += data + (b"\x00" if e.subindex == 0 and len(data) == 1 else b"")
        return bytes(out)

    def write(self, index: int, subindex: int, data: bytes) -> None:
        """SDO download of ``data``; raises SdoAbort with the CiA 301 abort code."""
        e = self.entry(index, subindex)
        if e.access in ("ro", "const"):
            raise SdoAbort(codes.ABORT_READ_ONLY, index, subindex)
        if e.kind == "str":
            e.value = bytes(data)
            return
        fmt = KINDS[e.kind][0]
        size = struct.calcsize(fmt)
        if len(data) != size:
            raise SdoAbort(codes.ABORT_LENGTH, index, subindex)
        value = int(struct.unpack(fmt, data)[0])
        if e.low is not None and value < e.low:
            raise SdoAbort(codes.ABORT_VALUE_LOW, index, subindex)
        if e.high is not None and value > e.high:
            raise SdoAbort(codes.ABORT_VALUE_HIGH, index, subindex)
        if _is_mapping(index) or index in (RXPDO_ASSIGN_INDEX, TXPDO_ASSIGN_INDEX):
            self._check_pdo_write(index, subindex, value)
        e.set(value)

    # ----------------------------------------------------------------- PDO mapping

    def _check_pdo_write(self, index: int, subindex: int, value: int) -> None:
        # CiA 301 sequence: sub 0 := 0, write the entries, sub 0 := count (validated here).
        if self.pdo_locked:
            raise SdoAbort(codes.ABORT_DEVICE_STATE, index, subindex)
        if self.mapping_needs_invalid_pdo and _is_mapping(index):
            comm = (index - _COMM_OF_MAPPING, 1)  # 0x1600 -> 0x1400, 0x1A00 -> 0x1800
            if comm in self._entries and not self._entries[comm].get() & COB_ID_INVALID:
                raise SdoAbort(codes.ABORT_VALUE_RANGE, index, subindex)
        if index in (RXPDO_ASSIGN_INDEX, TXPDO_ASSIGN_INDEX):
            if subindex > 0 and value not in self.assignable.get(index, ()):
                raise SdoAbort(codes.ABORT_VALUE_RANGE, index, subindex)
            if subindex == 0 and value > len(self.subentries(index)) - 1:
                raise SdoAbort(codes.ABORT_VALUE_HIGH, index, subindex)
            return
        if subindex > 0:
            if self.get(index, 0) != 0:
                raise SdoAbort(codes.ABORT_SUBINDEX0_NOT_ZERO, index, subindex)
            self._check_mapped_object(index, subindex, value)
            return
        if value > MAX_PDO_ENTRIES:
            raise SdoAbort(codes.ABORT_VALUE_HIGH, index, subindex)
        bits = 0
        for sub in range(1, value + 1):
            raw = self.get(index, sub)
            self._check_mapped_object(index, sub, raw)
            bits += raw & 0xFF
        if bits > self.max_pdo_bits:
            raise SdoAbort(codes.ABORT_PDO_LENGTH, index, subindex)

    def _check_mapped_object(self, index: int, subindex: int, raw: int) -> None:
        target = parse_mapping_value(raw)
        if target.index == 0 and target.subindex == 0:  # padding: a gap of that many bits
            return
        e = self._entries.get((target.index, target.subindex))
        if e is None:
            raise SdoAbort(codes.ABORT_NO_OBJECT, index, subindex)
        wants_rx = 0x1600 <= index < 0x1800
        direction_ok = (e.access in ("rw", "wo")) if wants_rx else (e.access != "wo")
        if not e.pdo_mappable or not direction_ok:
            raise SdoAbort(codes.ABORT_NOT_MAPPABLE, index, subindex)
        if target.bit_length != e.size * 8:
            raise SdoAbort(codes.ABORT_PDO_LENGTH, index, subindex)

    def mapping(self, index: int) -> list[PdoEntry]:
        """The PDO mapping currently in ``index`` (0x1600 or 0x1A00)."""
        n = self.get(index, 0)
        return [parse_mapping_value(self.get(index, s)) for s in range(1, n + 1)]


def _is_mapping(index: int) -> bool:
    """RxPDO (0x1600-0x17FF) or TxPDO (0x1A00-0x1BFF) mapping object."""
    return 0x1600 <= index < 0x1800 or 0x1A00 <= index < 0x1C00


# ------------------------------------------------------------------- CiA 402 drive


@dataclass
class DriveObjects:
    """Live arrays an emulated drive binds into its dictionary (each shape (n_axes,)).

    ``rx``/``tx`` are process-image records; the rest are drive parameters in raw units.
    """

    rx: np.ndarray
    tx: np.ndarray
    max_torque: np.ndarray  # 0x6072 [per mille], u16
    quick_stop_decel: np.ndarray  # 0x6085 [counts/s²], u32
    following_window: np.ndarray  # 0x6065 [counts], u32
    following_timeout: np.ndarray  # 0x6066 [ms], u16
    quick_stop_option: np.ndarray  # 0x605A, i16
    error_register: np.ndarray  # 0x1001, u8


def cia402_dictionary(
    axis: int,
    objs: DriveObjects,
    *,
    vendor_id: int,
    product_code: int,
    revision: int,
    serial: int,
    device_name: str,
    counts_per_rev: int,
    gear_motor_revs: int,
    gear_shaft_revs: int,
    rated_torque_mnm: int,
    rated_current_ma: int,
) -> ObjectDictionary:
    """The object dictionary of one emulated CiA-402 servo drive (axis ``axis``)."""
    od = ObjectDictionary(device_name)
    rx, tx = objs.rx, objs.tx

    od.add_var(0x1000, "device type", "u32", "ro", 0x00020192)  # CiA 402, servo drive
    od.add_var(0x1001, "error register", "u8", "ro", bound=(objs.error_register, axis))
    od.add_var(0x1008, "manufacturer device name", "str", "const", device_name.encode())
    od.add_var(0x100A, "manufacturer software version", "str", "const", b"hofto-sim 1")
    od.add_record(
        0x1018,
        "identity",
        [
            OdEntry(0x1018, 1, "vendor id", "u32", "ro", vendor_id),
            OdEntry(0x1018, 2, "product code", "u32", "ro", product_code),
            OdEntry(0x1018, 3, "revision number", "u32", "ro", revision),
            OdEntry(0x1018, 4, "serial number", "u32", "ro", serial),
        ],
    )
    for index, name, mapping in (
        (RXPDO_INDEX, "RxPDO mapping 1", RXPDO_MAPPING),
        (TXPDO_INDEX, "TxPDO mapping 1", TXPDO_MAPPING),
    ):
        subs = [
            OdEntry(index, i + 1, f"mapped object {i + 1}", "u32", "rw", mapping_value(m))
            for i, m in enumerate(mapping)
        ]
        subs += [
            OdEntry(index, i + 1, f"mapped object {i + 1}", "u32", "rw", 0)
            for i in range(len(mapping), MAX_PDO_ENTRIES)
        ]
        od.add(OdEntry(index, 0, "number of mapped objects", "u8", "rw", len(mapping)), name)
        for e in subs:
            od.add(e, name)
    # Sync manager communication types: mailbox out, mailbox in, outputs, inputs.
    od.add_record(
        0x1C00,
        "sync manager communication type",
        [OdEntry(0x1C00, i + 1, f"SM{i} type", "u8", "ro", t) for i, t in enumerate((1, 2, 3, 4))],
    )
    for index, name, pdo in (
        (RXPDO_ASSIGN_INDEX, "SM2 PDO assignment", RXPDO_INDEX),
        (TXPDO_ASSIGN_INDEX, "SM3 PDO assignment", TXPDO_INDEX),
    ):
        od.add(OdEntry(index, 0, "number of assigned PDOs", "u8", "rw", 1), name)
        od.add(OdEntry(index, 1, "assigned PDO 1", "u16", "rw", pdo), name)

    od.add_var(0x603F, "error code", "u16", "ro", bound=(tx["error_code"], axis), pdo_mappable=True)
    od.add_var(
        0x6040, "controlword", "u16", "rw", bound=(rx["controlword"], axis), pdo_mappable=True
    )
    od.add_var(0x6041, "statusword", "u16", "ro", bound=(tx["statusword"], axis), pdo_mappable=True)
    od.add_var(
        0x605A,
        "quick stop option code",
        "i16",
        "rw",
        low=0,
        high=8,
        bound=(objs.quick_stop_option, axis),
    )
    od.add_var(0x605E, "fault reaction option code", "i16", "ro", 2)
    od.add_var(
        0x6060, "modes of operation", "i8", "rw", bound=(rx["mode"], axis), pdo_mappable=True
    )
    od.add_var(
        0x6061,
        "modes of operation display",
        "i8",
        "ro",
        bound=(tx["mode_display"], axis),
        pdo_mappable=True,
    )
    od.add_var(
        0x6064,
        "position actual value",
        "i32",
        "ro",
        bound=(tx["position"], axis),
        pdo_mappable=True,
    )
    od.add_var(0x6065, "following error window", "u32", "rw", bound=(objs.following_window, axis))
    od.add_var(
        0x6066, "following error time out", "u16", "rw", bound=(objs.following_timeout, axis)
    )
    od.add_var(
        0x606C,
        "velocity actual value",
        "i32",
        "ro",
        bound=(tx["velocity"], axis),
        pdo_mappable=True,
    )
    od.add_var(
        0x6071, "target torque", "i16", "rw", bound=(rx["target_torque"], axis), pdo_mappable=True
    )
    od.add_var(0x6072, "max torque", "u16", "rw", bound=(objs.max_torque, axis))
    od.add_var(0x6075, "motor rated current", "u32", "ro", rated_current_ma)
    od.add_var(0x6076, "motor rated torque", "u32", "ro", rated_torque_mnm)
    od.add_var(
        0x6077, "torque actual value", "i16", "ro", bound=(tx["torque"], axis), pdo_mappable=True
    )
    od.add_var(
        0x6078, "current actual value", "i16", "ro", bound=(tx["current"], axis), pdo_mappable=True
    )
    od.add_var(
        0x607A,
        "target position",
        "i32",
        "rw",
        bound=(rx["target_position"], axis),
        pdo_mappable=True,
    )
    od.add_var(
        0x6085, "quick stop deceleration", "u32", "rw", low=1, bound=(objs.quick_stop_decel, axis)
    )
    od.add_record(
        0x608F,
        "position encoder resolution",
        [
            OdEntry(0x608F, 1, "encoder increments", "u32", "ro", counts_per_rev),
            OdEntry(0x608F, 2, "motor revolutions", "u32", "ro", 1),
        ],
    )
    od.add_record(
        0x6091,
        "gear ratio",
        [
            OdEntry(0x6091, 1, "motor revolutions", "u32", "ro", gear_motor_revs),
            OdEntry(0x6091, 2, "shaft revolutions", "u32", "ro", gear_shaft_revs),
        ],
    )
    od.add_var(
        0x60B2, "torque offset", "i16", "rw", bound=(rx["torque_offset"], axis), pdo_mappable=True
    )
    od.add_var(
        0x60FD, "digital inputs", "u32", "ro", bound=(tx["digital_inputs"], axis), pdo_mappable=True
    )
    od.add_var(
        0x60FF,
        "target velocity",
        "i32",
        "rw",
        bound=(rx["target_velocity"], axis),
        pdo_mappable=True,
    )
    od.add_var(
        0x6502, "supported drive modes", "u32", "ro", (1 << 7) | (1 << 8) | (1 << 9)
    )  # bits 7/8/9: CSP, CSV, CST
    for (index, sub), t in OBJECT_TYPES.items():  # every PDO object must be present
        if (index, sub) not in EXTRA_FIELDS:  # mode-specific ones: added by the modes' drives
            assert (index, sub) in od, f"0x{index:04X} missing ({t})"
    return od


# ------------------------------------------------------------------ drive profiles


def impersonate(od: ObjectDictionary, profile: Any, serial: int) -> None:
    """Turn a :func:`cia402_dictionary` into the dictionary of the drive ``profile``
    (a :class:`hofto_hw.config.drive_profile.DriveProfile`) describes: its identity, only
    the CiA-402 objects it has (``objects.absent`` and ``objects.absent_settings`` removed:
    an SDO to one aborts 0x06020000), its PDO mapping objects with their default mapping
    (fixed ones read-only: a write aborts 0x06010002 as a real drive's does; configurable
    ones writable in PRE-OP only), the assignment accepting only its own PDOs, the vendor
    objects it maps (plain values), 0x6502 from its modes."""
    from hofto_hw.config.drive_profile import FIELD_OBJECTS, MODE_BITS, SETTING_OBJECTS

    ident = profile.identity
    for sub, value in (
        (1, ident.vendor_id),
        (2, ident.product_code),
        (3, ident.revision_min or 0),
        (4, serial),
    ):
        od.entry(0x1018, sub).value = value
    for name in profile.objects.absent:
        od.remove(FIELD_OBJECTS[name])
    for name in profile.objects.absent_settings:  # an SDO to one aborts 0x06020000
        od.remove(SETTING_OBJECTS[name][0])
    units = profile.units
    for index, obj in ((0x608F, units.position_encoder_resolution), (0x6091, units.gear_ratio)):
        if not obj.present:
            od.remove(index)
    od.entry(0x6502, 0).value = sum(1 << MODE_BITS[m] for m in profile.modes.supported)
    kinds = {8: "u8", 16: "u16", 32: "u32"}
    for w in profile.startup:  # the objects its start-up writes go to exist in the drive
        if (w.index, w.subindex) in od or w.bits not in kinds:
            continue
        if w.subindex and (w.index, 0) not in od:
            od.add(OdEntry(w.index, 0, "highest sub-index", "u8", "ro", w.subindex))
        od.add(OdEntry(w.index, w.subindex, w.comment or "start-up object", kinds[w.bits]))
    od.remove(RXPDO_INDEX)
    od.remove(TXPDO_INDEX)
    max_entries = profile.canopen.max_entries if profile.canopen is not None else 8
    for assign, pdos, rx in (
        (RXPDO_ASSIGN_INDEX, profile.rx_pdos, True),
        (TXPDO_ASSIGN_INDEX, profile.tx_pdos, False),
    ):
        for p in pdos:
            access = "ro" if p.fixed else "rw"
            n_subs = len(p.entries) if p.fixed else max(len(p.entries), max_entries)
            name = f"{'Rx' if rx else 'Tx'}PDO 0x{p.index:04X}"
            od.add(
                OdEntry(p.index, 0, "number of mapped objects", "u8", access, len(p.entries)), name
            )
            for k in range(n_subs):
                value = 0
                if k < len(p.entries):
                    e = p.entries[k]
                    value = (e.index << 16) | (e.subindex << 8) | e.bits
                    if e.index and (e.index, e.subindex) not in od:
                        kind = {8: "u8", 16: "u16", 32: "u32"}.get(e.bits, "u32")
                        od.add(
                            OdEntry(
                                e.index,
                                e.subindex,
                                f"vendor object 0x{e.index:04X}",
                                kind,
                                "rw" if rx else "ro",
                                0,
                                pdo_mappable=True,
                            )
                        )
                od.add(
                    OdEntry(p.index, k + 1, f"mapped object {k + 1}", "u32", access, value), name
                )
        od.remove(assign)
        subs = [
            OdEntry(
                assign,
                k + 1,
                f"assigned PDO {k + 1}",
                "u16",
                "rw",
                pdos[k].index if k < len(pdos) else 0,
            )
            for k in range(max(len(pdos), 4))
        ]
        od.add(
            OdEntry(assign, 0, "number of assigned PDOs", "u8", "rw", len(pdos)),
            "SM2 PDO assignment" if rx else "SM3 PDO assignment",
        )
        for e in subs:
            od.add(e)
        od.assignable[assign] = frozenset(p.index for p in pdos)


# ------------------------------------------------------------ multi-axis devices


class MultiAxisDictionary:
    """The dictionary of a k-axis drive device (CiA 402-1) as one device shows it on the bus.

    ``axes[k]``: the dictionary of the emulated drive of axis k (None: no drive emulates
    that axis). CiA-402 objects of axis k (0x6000 + 0x800·k .. + 0x7FF, k >= 1) go to axis
    k's dictionary at the axis-0 index; everything else (identity, PDO mapping and
    assignment, the axis-0 objects) to axis 0's. ``pdo_locked`` applies to every axis.
    """

    def __init__(self, axes: Sequence[ObjectDictionary | None]) -> None:
        first = axes[0]
        if first is None:
            raise ValueError("axis 0 of a multi-axis device needs a dictionary")
        self.axes = list(axes)
        self.first: ObjectDictionary = first

    def _route(self, index: int) -> tuple[ObjectDictionary, int]:
        if 0x6800 <= index <= 0x9FFF:
            k, base = divmod(index - 0x6000, 0x800)
            od = self.axes[k] if k < len(self.axes) else None
            if od is not None:
                return od, 0x6000 + base
        return self.first, index

    @property
    def pdo_locked(self) -> bool:
        return self.first.pdo_locked

    @pdo_locked.setter
    def pdo_locked(self, value: bool) -> None:
        for od in self.axes:
            if od is not None:
                od.pdo_locked = value

    def __contains__(self, key: tuple[int, int]) -> bool:
        od, index = self._route(key[0])
        return (index, key[1]) in od

    def entry(self, index: int, subindex: int) -> OdEntry:
        od, at = self._route(index)
        return od.entry(at, subindex)

    def get(self, index: int, subindex: int = 0) -> int:
        od, at = self._route(index)
        return od.get(at, subindex)

    def read(self, index: int, subindex: int) -> bytes:
        od, at = self._route(index)
        try:
            return od.read(at, subindex)
        except SdoAbort as a:
            raise SdoAbort(a.code, index, subindex) from None

    def write(self, index: int, subindex: int, data: bytes) -> None:
        od, at = self._route(index)
        try:
            od.write(at, subindex, data)
        except SdoAbort as a:
            raise SdoAbort(a.code, index, subindex) from None

    def read_complete(self, index: int) -> bytes:
        od, at = self._route(index)
        return od.read_complete(at)

    def mapping(self, index: int) -> list[PdoEntry]:
        return self.first.mapping(index)
