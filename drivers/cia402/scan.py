"""What a live bus says about its drives, and the draft drive profile made of it.

The bus readers (:mod:`drivers.ethercat.scan`, :mod:`drivers.canopen.scan`) fill one
:class:`ScannedDrive` per drive: identity, the PDOs it runs now (assignment / enabled PDOs and
their mappings, read back), which CiA-402 objects its dictionary has, 0x6502, the units
objects, EtherCAT's DC op mode from the SII, CANopen's PDO communication parameters.
:func:`draft_profile` turns that into a :class:`~hofto_hw.config.drive_profile.DriveProfile`
a user reviews: the layout is the one the drive runs (each PDO fixed or configurable as the
scan found it; a PDO the scan could not probe is marked fixed: the master then only assigns
and reads back, it does not rewrite a mapping it cannot know to be writable), the
fallbacks are chosen for what is not mapped, and the start-up writes are those the drive's
dictionary calls for (the mode when 0x6060 is not mapped; the interpolation period when
0x60C2 exists).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from drivers.errors import DriverError
from hofto_hw.config.drive_profile import (
    CIA402_OBJECTS,
    FIELD_OBJECTS,
    LOOP_OBJECTS,
    MODE_NUMBERS,
    DriveProfile,
    cia402_object,
    modes_from_bits,
)


class ScanError(DriverError):
    """The bus cannot be scanned as it is (one line naming the device)."""


@dataclass
class ScannedPdo:
    """One PDO as the drive runs it: mapping object, entries (index, sub, bits) in wire
    order; CANopen: COB-ID base, transmission type, enabled (COB-ID bit 31 clear)."""

    index: int
    entries: list[tuple[int, int, int]]
    cob_id_base: int | None = None
    transmission_type: int | None = None
    enabled: bool = True
    #: True: the mapping refused a write (fixed); False: it took one (configurable); None:
    #: not probed (the draft then says fixed: the master only assigns it)
    fixed: bool | None = None


@dataclass
class ScannedDrive:
    """One drive on the bus (see module docstring). ``address``: 'slave 2' / 'node 5'."""

    bus: str
    address: str
    name: str
    vendor_id: int
    product_code: int
    revision: int
    rx_pdos: list[ScannedPdo]
    tx_pdos: list[ScannedPdo]
    #: index -> True for every object of interest the dictionary has
    objects: set[int] = field(default_factory=set)
    supported_modes: int | None = None  # 0x6502
    units: dict[int, tuple[int, int]] = field(default_factory=dict)  # 0x608F/0x6091/0x6092
    dc: dict[str, int] | None = None  # assign_activate, sync0_cycle_ns, sync0_shift_ns
    max_entries: int | None = None  # CANopen: mapping sub-indices per PDO
    bitrate: int | None = None

    def key(self) -> tuple[Any, ...]:
        """What makes two drives the same model running the same layout."""
        return (
            self.bus,
            self.vendor_id,
            self.product_code,
            self.revision,
            tuple((p.index, tuple(p.entries)) for p in self.rx_pdos),
            tuple((p.index, tuple(p.entries)) for p in self.tx_pdos),
        )


#: objects a scan asks the dictionary for (besides the mapped ones)
PROBED_OBJECTS = tuple(sorted(FIELD_OBJECTS[n] for n in LOOP_OBJECTS)) + (0x60C2, 0x6502)


def check_unique(addresses: Sequence[tuple[int, str]], what: str) -> None:
    """Refuse two drives claiming one ``what`` (station alias, node id): ``addresses`` are
    (value, who) pairs; value 0 (no alias) is not a claim."""
    seen: dict[int, str] = {}
    for value, who in addresses:
        if value and value in seen:
            raise ScanError(
                f"{seen[value]} and {who} both claim {what} {value}: give each "
                "drive its own before scanning"
            )
        seen.setdefault(value, who)


def _slug(text: str) -> str:
    s = re.sub(r"[^a-z0-9]+", "_", text.lower()).strip("_")
    return s or "drive"


def draft_profile(d: ScannedDrive, name: str | None = None) -> DriveProfile:
    """The draft profile of a scanned drive (see module docstring)."""
    mapped: set[str] = set()
    for p in d.rx_pdos + d.tx_pdos:
        for index, sub, _bits in p.entries:
            found = cia402_object(index) if sub == 0 else None
            if found and found[1] == 0 and found[0] in CIA402_OBJECTS:
                mapped.add(CIA402_OBJECTS[found[0]][0])
    modes = modes_from_bits(d.supported_modes) if d.supported_modes else []
    cyclic = [
        m
        for m, target in (
            ("csp", "target_position"),
            ("csv", "target_velocity"),
            ("cst", "target_torque"),
        )
        if target in mapped and (not modes or m in modes)
    ]
    if not cyclic:
        raise ScanError(f"{d.address} ({d.name}): maps no target of a cyclic synchronous mode")
    loop = cyclic[0]
    supported = modes or cyclic
    transition = "PS" if d.bus == "ethercat" else "PO"
    startup: list[dict[str, Any]] = []
    if 0x60C2 in d.objects and d.bus == "ethercat":
        startup += [
            {
                "index": 0x60C2,
                "subindex": 1,
                "value": "loop_period",
                "bits": 8,
                "transition": transition,
                "comment": "interpolation period: the loop period",
            },
            {
                "index": 0x60C2,
                "subindex": 2,
                "value": -3,
                "bits": 8,
                "transition": transition,
                "comment": "interpolation period unit: ms",
            },
        ]
    set_by = "pdo"
    if "mode" not in mapped:
        set_by = "startup"
        startup.append(
            {
                "index": 0x6060,
                "subindex": 0,
                "value": MODE_NUMBERS[loop],
                "bits": 8,
                "transition": transition,
                "comment": f"mode {loop} (0x6060 not mapped)",
            }
        )
    present = {n for n in LOOP_OBJECTS if FIELD_OBJECTS[n] in d.objects} | mapped
    fallbacks: dict[str, str] = {}
    for n in LOOP_OBJECTS:
        if n in mapped:
            continue
        if n == "mode":
            how = "startup"
        elif n == "mode_display":
            how = "sdo" if n in present else "unavailable"
        elif n == "torque_offset":
            how = "target_torque_in_cst" if "target_torque" in mapped else "unavailable"
        elif n == "velocity":
            how = "position_derivative"
        elif n == "torque":
            how = "current" if "current" in mapped else "unavailable"
        elif n == "error_code":
            how = "sdo" if n in present or d.bus == "ethercat" else "emcy"
        elif n == "digital_inputs":
            how = "none"
        else:
            how = "unavailable"
        fallbacks[n] = how
    data: dict[str, Any] = {
        "profile": 1,
        "name": name or f"{_slug(d.name)}_{d.product_code:08x}",
        "description": f"draft from `hofto-hw bus scan` of {d.address} ({d.name}): review it",
        "source": {"file": "bus scan", "device": d.name},
        "identity": {
            "vendor_id": d.vendor_id,
            "product_code": d.product_code,
            "revision_min": d.revision,
        },
        "bus": d.bus,
        "axes": _axes(d),
        "modes": {"supported": supported, "loop": loop, "set_by": set_by},
        "rx_pdos": [_pdo(p) for p in d.rx_pdos],
        "tx_pdos": [_pdo(p) for p in d.tx_pdos],
        "objects": {
            "mapped": sorted(mapped & set(LOOP_OBJECTS)),
            "sdo": sorted(present - mapped),
            "absent": sorted(set(LOOP_OBJECTS) - present),
        },
        "fallbacks": fallbacks,
        "startup": startup,
        "units": {
            key: {
                "present": index in d.units,
                "default": list(d.units[index]) if index in d.units else None,
            }
            for key, index in (
                ("position_encoder_resolution", 0x608F),
                ("gear_ratio", 0x6091),
                ("feed_constant", 0x6092),
            )
        },
    }
    if d.dc is not None:
        data["dc"] = {
            "assign_activate": d.dc["assign_activate"],
            "sync0_cycle_ns": d.dc["sync0_cycle_ns"] or None,
            "sync0_shift_ns": d.dc["sync0_shift_ns"],
        }
    if d.bus == "canopen":
        data["canopen"] = {
            "bitrates": [d.bitrate or 1_000_000],
            "max_entries": d.max_entries or 8,
            "rpdo": [_comm(p) for p in d.rx_pdos],
            "tpdo": [_comm(p) for p in d.tx_pdos],
        }
    return DriveProfile.model_validate(data)


def _axes(d: ScannedDrive) -> int:
    """CiA-402 axes the drive's PDOs map objects of (axis k at 0x6000 + 0x800·k)."""
    most = 0
    for p in d.rx_pdos + d.tx_pdos:
        for index, sub, _bits in p.entries:
            found = cia402_object(index) if sub == 0 else None
            if found and found[0] in CIA402_OBJECTS:
                most = max(most, found[1])
    return most + 1


def _pdo(p: ScannedPdo) -> dict[str, Any]:
    return {
        "index": p.index,
        "fixed": p.fixed is not False,
        "entries": [{"index": i, "subindex": s, "bits": b} for i, s, b in p.entries],
    }


def _comm(p: ScannedPdo) -> dict[str, Any]:
    return {
        "cob_id_base": p.cob_id_base,
        "transmission_type": p.transmission_type,
        "enabled_by_default": p.enabled,
    }
