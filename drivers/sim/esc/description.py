"""What one emulated EtherCAT slave looks like from the bus: identity, memory layout, features.

A :class:`SlaveDescription` is plain data. The SII EEPROM image (``sii.py``), the register
defaults and the CoE communication objects of an emulated slave are all derived from it, so a
configuration file (identity per axis) is enough to describe the emulated network.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from itertools import pairwise
from typing import Any

from drivers.cia402 import pdo
from hofto_hw.config.drives import DriveConfig

#: Mailbox protocol bits of SII word 0x1C.
MBX_PROTO_AOE = 0x01
MBX_PROTO_EOE = 0x02
MBX_PROTO_COE = 0x04
MBX_PROTO_FOE = 0x08

#: CoE details bits of the SII General category.
COE_SDO = 0x01
COE_SDO_INFO = 0x02
COE_PDO_ASSIGN = 0x04
COE_PDO_CONFIG = 0x08
COE_UPLOAD_AT_STARTUP = 0x10
COE_COMPLETE_ACCESS = 0x20

#: SyncManager types of the SII SyncM category (and of object 0x1C00).
SM_TYPE_MBX_OUT = 1
SM_TYPE_MBX_IN = 2
SM_TYPE_OUTPUTS = 3
SM_TYPE_INPUTS = 4


@dataclass(frozen=True)
class SlaveDescription:
    """One emulated slave.

    Offsets are physical ESC addresses [byte]; sizes are in bytes. ``mbx_out`` is SM0
    (master -> slave), ``mbx_in`` is SM1 (slave -> master), ``outputs`` is SM2 (RxPDO),
    ``inputs`` is SM3 (TxPDO).
    """

    vendor_id: int
    product_code: int
    revision: int
    serial: int = 0
    alias: int = 0
    name: str = "hofto-hw emulated CiA-402 drive"
    group: str = "Drives"
    mbx_out_offset: int = 0x1000
    mbx_out_size: int = 128
    mbx_in_offset: int = 0x1080
    mbx_in_size: int = 128
    outputs_offset: int = 0x1100
    inputs_offset: int = 0x1180
    max_pdo_bytes: int = 64
    complete_access: bool = True
    dc_supported: bool = True
    sm_watchdog_ms: float = 100.0
    #: the drive refuses OP without SYNC0 (its profile has a ``dc`` section): AL 0x0030
    dc_required: bool = False
    #: SYNC0 cycle the drive insists on [ns] (None: any)
    sync0_cycle_ns: int | None = None
    #: SYNC0 shift [ns] and AssignActivate of its DC op mode (the SII's DC category)
    sync0_shift_ns: int = 0
    assign_activate: int = 0

    def __post_init__(self) -> None:
        for name in ("vendor_id", "product_code", "revision", "serial"):
            v = getattr(self, name)
            if not 0 <= v <= 0xFFFFFFFF:
                raise ValueError(f"{name} = {v} does not fit in 32 bits")
        if not 0 <= self.alias <= 0xFFFF:
            raise ValueError(f"alias = {self.alias} does not fit in 16 bits")
        regions = [
            ("mbx_out", self.mbx_out_offset, self.mbx_out_size),
            ("mbx_in", self.mbx_in_offset, self.mbx_in_size),
            ("outputs", self.outputs_offset, self.max_pdo_bytes),
            ("inputs", self.inputs_offset, self.max_pdo_bytes),
        ]
        for name, start, size in regions:
            if start < 0x1000 or start + size > 0x10000:
                raise ValueError(f"{name} area 0x{start:04X}+{size} is outside process RAM")
        regions.sort(key=lambda r: r[1])
        for (n1, s1, l1), (n2, s2, _) in pairwise(regions):
            if s1 + l1 > s2:
                raise ValueError(f"{n1} area overlaps {n2} area")
        if not 16 <= self.mbx_out_size <= 1024 or not 16 <= self.mbx_in_size <= 1024:
            raise ValueError("mailbox sizes must be 16..1024 bytes")

    @property
    def coe_details(self) -> int:
        """CoE details byte of the SII General category."""
        bits = COE_SDO | COE_PDO_ASSIGN | COE_PDO_CONFIG
        if self.complete_access:
            bits |= COE_COMPLETE_ACCESS
        return bits

    @property
    def default_outputs_size(self) -> int:
        """SM2 length for the default RxPDO mapping [byte]."""
        return pdo.RXPDO_SIZE

    @property
    def default_inputs_size(self) -> int:
        """SM3 length for the default TxPDO mapping [byte]."""
        return pdo.TXPDO_SIZE


def slave_descriptions(
    drives: Sequence[DriveConfig], profiles: Sequence[Any] | None = None
) -> list[SlaveDescription]:
    """One slave per drive device (``bus.drives[i].device``; one per drive unless several
    share a multi-axis device, described by the first of them): identity from
    ``drives[i].identity`` (``bus.drives``), or, for a drive with a profile (``profiles[i]``,
    a DriveProfile; None: none), the profile's identity, name and DC requirements."""
    from hofto_hw.config.drives import device_map

    out = []
    described: set[int] = set()
    for i, (d, (dev, _k)) in enumerate(zip(drives, device_map(drives), strict=True)):
        if dev in described:
            continue
        described.add(dev)
        ident = d.identity
        prof = profiles[i] if profiles is not None else None
        if prof is not None and not prof.name.startswith("builtin-"):
            dc = prof.dc
            out.append(
                SlaveDescription(
                    vendor_id=prof.identity.vendor_id,
                    product_code=prof.identity.product_code,
                    revision=prof.identity.revision_min or 0,
                    serial=0x5100 + i,
                    name=prof.name[:60],
                    dc_required=dc is not None,
                    sync0_cycle_ns=dc.sync0_cycle_ns if dc is not None else None,
                    sync0_shift_ns=dc.sync0_shift_ns if dc is not None else 0,
                    assign_activate=dc.assign_activate if dc is not None else 0,
                )
            )
            continue
        out.append(
            SlaveDescription(
                vendor_id=ident.vendor_id,
                product_code=ident.product_code,
                revision=ident.revision or 0,
                serial=0x5100 + i,
                name="hofto-sim CiA-402 servo",
            )
        )
    return out
