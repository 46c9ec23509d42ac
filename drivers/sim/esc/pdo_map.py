"""From a drive's PDO mapping objects to byte-copy plans between SyncManagers and records.

The emulated slave reads what the master wrote into 0x1C12/0x1C13 and 0x1600/0x1A00 (the
drive's :class:`~drivers.sim.object_dictionary.ObjectDictionary` stores and checks those
writes) when it goes PRE-OP -> SAFE-OP, checks that the drive can run with it, and turns it
into a copy plan: contiguous runs of ``(sm_offset, record_offset, size)`` bytes. With the
default mapping each plan is one run of the whole record.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from drivers.cia402 import pdo
from drivers.sim.object_dictionary import ObjectDictionary


def pdo_known_indices() -> set[int]:
    """Object indices of the canonical process image (others are carried, not decoded)."""
    return {index for index, _sub in pdo.OBJECT_FIELDS}


#: (sm_offset, record_offset, size) in bytes.
CopyPlan = tuple[tuple[int, int, int], ...]


def assigned_entries(od: ObjectDictionary, assign_index: int) -> list[pdo.PdoEntry]:
    """Mapped objects of every PDO assigned to a SyncManager, in process-image order."""
    out: list[pdo.PdoEntry] = []
    for sub in range(1, od.get(assign_index, 0) + 1):
        out.extend(od.mapping(od.get(assign_index, sub)))
    return out


def copy_plan(
    entries: list[pdo.PdoEntry], dtype: np.dtype, records: Sequence[int | None] | None = None
) -> tuple[CopyPlan, int]:
    """Copy plan for ``entries`` against record ``dtype`` and the SM length it needs [byte].

    ``records``: per CiA-402 axis k of the device (objects at 0x6000 + 0x800·k), the index of
    its record in an array of records (record offsets then count from that array's start);
    None (an axis no drive emulates): its objects are carried, not decoded. Default: one
    axis, offsets within its record.

    Raises ``ValueError`` naming an object that is not a field of ``dtype``.
    """
    from drivers.cia402.wire import split_object

    records = [0] if records is None else list(records)
    runs: list[list[int]] = []
    sm_off = 0
    for e in entries:
        size = e.bit_length // 8
        found = split_object(e.index, e.subindex) if e.index else None
        k = found[1] if found is not None else 0
        rec = records[k] if k < len(records) else None
        if found is None or rec is None:
            if e.field or (e.index in pdo_known_indices() and found is None):
                raise ValueError(f"object 0x{e.index:04X}:{e.subindex:02X} is not in this PDO")
            sm_off += size  # padding or a vendor object: bytes on the wire, no record field
            continue
        field = pdo.OBJECT_FIELDS[(found[0], e.subindex)]
        if field not in (dtype.names or ()):
            raise ValueError(f"object 0x{e.index:04X}:{e.subindex:02X} is not in this PDO")
        rec_off = rec * dtype.itemsize + dtype.fields[field][1]
        last = runs[-1] if runs else None
        if last and last[0] + last[2] == sm_off and last[1] + last[2] == rec_off:
            last[2] += size
        else:
            runs.append([sm_off, rec_off, size])
        sm_off += size
    return tuple((a, b, c) for a, b, c in runs), sm_off


def check_mapping(entries: list[pdo.PdoEntry], required: str, dtype: np.dtype) -> str | None:
    """Why the drive cannot run with ``entries`` (``None`` when it can)."""
    fields = [e.field for e in entries if e.field]
    if any(e.bit_length % 8 for e in entries):
        return "an entry is not a whole number of bytes"
    if required not in fields:
        return f"mapping lacks {required}"
    if len(set(fields)) != len(fields):
        return "an object is mapped twice"
    if any(f not in dtype.names for f in fields):
        return "an object is mapped in the wrong direction"
    return None
