"""What a vendor file says about one drive, whatever its format (ESI XML or EDS/DCF).

The importers (:mod:`drivers.profiles.esi`, :mod:`drivers.profiles.eds`) read a file into a
:class:`DeviceDescription`; :mod:`drivers.profiles.choose` turns that into a
:class:`~hofto_hw.config.drive_profile.DriveProfile`. Plain data, built once per import.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from hofto_hw.errors import UserError

Direction = Literal["rx", "tx"]


class ProfileImportError(UserError):
    """A vendor file cannot be imported; one line naming the file and what is wrong."""


@dataclass
class PdoOption:
    """One PDO the file describes (a mapping object 0x16xx/0x1Axx)."""

    index: int
    direction: Direction
    fixed: bool  # the mapping cannot be written (only assigned)
    entries: list[tuple[int, int, int]]  # (index, subindex, bits) in wire order; 0 = gap
    excludes: set[int] = field(default_factory=set)  # PDOs that cannot be assigned with it
    default: bool = False  # assigned by default (ESI Sm attribute; EDS: valid at power-on)
    mandatory: bool = False  # must always be assigned (ESI Mandatory="1")
    max_entries: int | None = None  # mapping sub-indices (configurable PDOs)
    name: str = ""

    @property
    def bits(self) -> int:
        """Total length [bit]."""
        return sum(e[2] for e in self.entries)


@dataclass
class ObjectInfo:
    """One object (or sub-index) of the dictionary."""

    index: int
    subindex: int
    bits: int | None
    mappable: str = ""  # "" not mappable, "rx", "tx" or "rxtx"
    default: int | None = None
    name: str = ""
    low: int | None = None  # EDS LowLimit / HighLimit (signed objects read as signed)
    high: int | None = None
    access: str = ""  # ro, rw, wo, rww, rwr, const ("" = not given)

    @property
    def writable(self) -> bool:
        """Whether an SDO may write it (access rw, wo, rww or rwr)."""
        return self.access in ("rw", "wo", "rww", "rwr")


@dataclass
class InitCommand:
    """A start-up write the file asks for (ESI InitCmd)."""

    index: int
    subindex: int
    value: int
    bits: int
    transitions: list[str]
    comment: str = ""


@dataclass
class DcMode:
    """One ESI ``<Dc><OpMode>``; cycle None = follows the master's cycle."""

    name: str
    assign_activate: int
    sync0_cycle_ns: int | None
    sync0_shift_ns: int
    sync1_cycle_ns: int | None = None
    sync1_shift_ns: int | None = None


@dataclass
class CanComm:
    """CANopen PDO communication parameter as the file's defaults give it."""

    cob_id_base: int  # COB-ID minus the node id
    transmission_type: int
    enabled: bool  # bit 31 of the default COB-ID clear


@dataclass
class DeviceDescription:
    """One device of a vendor file, format-independent."""

    path: Path
    sha256: str
    kind: Literal["esi", "igh-sii-dump", "eds"]
    bus: Literal["ethercat", "canopen"]
    device: str  # type/product name
    vendor_name: str
    vendor_id: int
    product_code: int
    revision: int | None
    pdos: list[PdoOption] = field(default_factory=list)
    objects: dict[tuple[int, int], ObjectInfo] = field(default_factory=dict)
    has_dictionary: bool = True
    init: list[InitCommand] = field(default_factory=list)
    dc: list[DcMode] = field(default_factory=list)
    sm_rx_bytes: int | None = None
    sm_tx_bytes: int | None = None
    pdo_assign: bool = True  # ESI CoE@PdoAssign: the PDO assignment may be changed
    pdo_config: bool = True  # ESI CoE@PdoConfig: configurable PDOs may be written
    # CANopen
    bitrates: list[int] = field(default_factory=list)
    comm: dict[int, CanComm] = field(default_factory=dict)  # mapping index -> communication
    heartbeat: bool = False
    node_id: int | None = None  # a DCF's [DeviceComissioning] NodeID
    notes: list[str] = field(default_factory=list)

    def has(self, index: int, subindex: int = 0) -> bool:
        """Whether the dictionary has ``index:subindex``."""
        return (index, subindex) in self.objects

    def default_of(self, index: int, subindex: int = 0) -> int | None:
        """The file's default value of an object, or None."""
        info = self.objects.get((index, subindex))
        return None if info is None else info.default


def file_sha256(raw: bytes) -> str:
    """Hex sha256 of a vendor file's bytes (recorded in the profile's ``source``)."""
    return hashlib.sha256(raw).hexdigest()


def read_vendor_file(path: Path, what: str, limit: int = 64 << 20) -> bytes:
    """The bytes of a vendor file, refusing a missing, empty, huge or binary one in one line."""
    try:
        size = path.stat().st_size
        if path.is_dir():
            raise ProfileImportError(f"{path}: is a folder, not a {what}")
        if size > limit:
            raise ProfileImportError(f"{path}: {size} bytes: too large for a {what}")
        raw = path.read_bytes()
    except FileNotFoundError:
        raise ProfileImportError(f"{path}: {what} not found") from None
    except OSError as exc:
        raise ProfileImportError(f"{path}: cannot read {what}: {exc.strerror}") from None
    if not raw.strip():
        raise ProfileImportError(f"{path}: {what} is empty")
    head = raw[:4096]
    controls = sum(b < 32 and b not in b"\t\n\r\f" for b in head)
    if b"\0" in head or (controls > 1 and 20 * controls > len(head)):
        raise ProfileImportError(f"{path}: is a binary file, not a {what}")
    return raw


def parse_number(text: str | None) -> int | None:
    """An integer written as ESI/EDS do: ``#x1A00``, ``0x1A00`` or decimal; None when empty."""
    if text is None:
        return None
    t = text.strip()
    if not t:
        return None
    sign = -1 if t.startswith("-") else 1
    t = t.lstrip("+-").strip()
    if t[:2] in ("#x", "#X", "0x", "0X"):
        return sign * int(t[2:], 16)
    return sign * int(t, 10)
