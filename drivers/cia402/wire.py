"""Per-axis wire layouts: the canonical process-image records <-> the bytes each drive sends.

The drive group and the tick read and write one canonical record per axis
(:data:`~drivers.cia402.pdo.RXPDO_DTYPE` / :data:`~drivers.cia402.pdo.TXPDO_DTYPE`, shape
(n,)) whatever the drives map. Each drive's own layout (its assigned PDOs, entries in wire
order, padding, objects it does not have) is an :class:`AxisLayout`. A :class:`WireImage`
precomputes, once, byte-index tables between the n canonical records and the n drives'
wire bytes laid end to end, so a whole bus of different layouts is encoded with ONE
``ndarray.take(..., out=, mode="clip")`` per direction and nothing is allocated per cycle
(the method, not ``np.take``: numpy 2.4's function wrapper costs ~3.7 µs a call against
~1 µs; ``mode="clip"`` because ``out`` is buffered under the default ``raise``):

- master side (:meth:`WireImage.encode_rx`, :meth:`WireImage.decode_tx`): canonical RxPDO
  -> wire outputs, wire inputs -> canonical TxPDO. Wire bytes no canonical field feeds
  (padding, objects the stack does not use) come from a zero byte; canonical TxPDO fields a
  drive does not report come from a per-axis defaults record (:meth:`set_default`), so they
  keep a defined value, and :attr:`WireImage.present` says per field and axis what the drive
  really has;
- drive side (:meth:`WireImage.drive_rx`, :meth:`WireImage.drive_tx`, for emulators):
  wire outputs -> the drive's canonical RxPDO (only the bytes it maps: what it does not map
  keeps what the drive had, e.g. a mode set by SDO), canonical TxPDO -> wire inputs.

Index 0 of a mapping entry is padding (CiA 301: a gap of ``bits`` bits). Entries must sit on
whole bytes (every CiA-402 drive file we know maps bytes); a bit layout that does not is
refused in one line (``LayoutError``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from drivers.cia402.pdo import (
    OBJECT_FIELDS,
    OBJECT_TYPES,
    RXPDO_DTYPE,
    RXPDO_INDEX,
    RXPDO_MAPPING,
    RXPDO_SIZE,
    TXPDO_DTYPE,
    TXPDO_INDEX,
    TXPDO_MAPPING,
    TXPDO_SIZE,
)
from drivers.errors import DriverError

#: canonical fields a drive must map (the stack cannot run an axis without them)
REQUIRED_RX = ("controlword",)
REQUIRED_TX = ("statusword", "position")
#: and at least one target (the profile's loop mode says which: position for csp and ip,
#: velocity for csv and pv, torque for cst)
TARGETS = ("target_position", "target_velocity", "target_torque")


class LayoutError(DriverError):
    """A PDO layout the stack cannot run (one line naming the axis and the entry)."""


class WireEntry(NamedTuple):
    """One mapping entry as the drive has it: object index, sub-index, length [bit].
    ``index == 0`` is padding."""

    index: int
    subindex: int
    bits: int


def _fmt(e: WireEntry) -> str:
    return f"0x{e.index:04X}:{e.subindex:02X}/{e.bits}"


@dataclass(frozen=True)
class AxisLayout:
    """The process data of one drive as it runs: entries of all assigned PDOs in wire order.

    ``rx``: master -> drive (SM2 / RPDOs), ``tx``: drive -> master (SM3 / TPDOs);
    ``rx_pdos`` / ``tx_pdos``: the assigned PDO indices (information).
    """

    rx: tuple[WireEntry, ...]
    tx: tuple[WireEntry, ...]
    rx_pdos: tuple[int, ...] = ()
    tx_pdos: tuple[int, ...] = ()

    @property
    def rx_size(self) -> int:
        """Output bytes on the wire."""
        return sum(e.bits for e in self.rx) // 8

    @property
    def tx_size(self) -> int:
        """Input bytes on the wire."""
        return sum(e.bits for e in self.tx) // 8

    def fields(self, direction: str, axis: int = 0) -> set[str]:
        """Canonical fields this layout carries in ``direction`` ('rx' or 'tx') for CiA-402
        axis ``axis`` of the device (its objects at 0x6000 + 0x800·axis)."""
        entries = self.rx if direction == "rx" else self.tx
        out = set()
        for e in entries:
            found = _split(e)
            if found is not None and found[1] == axis:
                out.add(OBJECT_FIELDS[(found[0], e.subindex)])
        return out

    def check(self, who: str = "drive", axes: Sequence[int] = (0,)) -> AxisLayout:
        """Raise LayoutError (one line naming ``who``) when the stack cannot run this layout:
        an entry off whole bytes, a known object with another length than its data type, an
        object mapped twice or in the wrong direction, controlword/target position or
        statusword/position or every target missing on one of the device's ``axes`` the stack
        runs. Returns self."""
        for direction, entries, dtype, required in (
            ("rx", self.rx, RXPDO_DTYPE, REQUIRED_RX),
            ("tx", self.tx, TXPDO_DTYPE, REQUIRED_TX),
        ):
            seen: set[tuple[int, int]] = set()
            for e in entries:
                if e.bits <= 0 or e.bits % 8:
                    raise LayoutError(
                        f"{who}: {direction} entry {_fmt(e)} is not a whole number of bytes "
                        "(odd bit layouts are not supported)"
                    )
                if e.index == 0:
                    continue
                if (e.index, e.subindex) in seen:
                    raise LayoutError(f"{who}: {direction} entry {_fmt(e)} is mapped twice")
                seen.add((e.index, e.subindex))
                found = _split(e)
                key = (found[0], e.subindex) if found is not None else (e.index, e.subindex)
                if key in OBJECT_TYPES:
                    size = np.dtype(OBJECT_TYPES[key]).itemsize * 8
                    if size != e.bits:
                        raise LayoutError(
                            f"{who}: {direction} entry {_fmt(e)}: the object is {size} bits"
                        )
                    if OBJECT_FIELDS[key] not in (dtype.names or ()):
                        raise LayoutError(
                            f"{who}: {direction} entry {_fmt(e)} belongs to the other direction"
                        )
            for k in axes:
                have = self.fields(direction, k)
                on = f" of axis {k}" if k else ""
                for f in required:
                    if f not in have:
                        raise LayoutError(f"{who}: the {direction} PDOs do not map {f}{on}")
                if direction == "rx" and not have & set(TARGETS):
                    raise LayoutError(
                        f"{who}: the rx PDOs map no target ({', '.join(TARGETS)}){on}"
                    )
        return self


def split_object(index: int, subindex: int) -> tuple[int, int] | None:
    """(axis-0 object index, device axis k) of a canonical CiA-402 object at
    ``0x6000 + 0x800·k`` (CiA 402-1: axis k of a multi-axis device); None for padding and
    objects the canonical image does not carry."""
    if not 0x6000 <= index <= 0x9FFF:
        return None
    k, base = divmod(index - 0x6000, 0x800)
    base += 0x6000
    return (base, k) if (base, subindex) in OBJECT_FIELDS else None


def _split(e: WireEntry) -> tuple[int, int] | None:
    return split_object(e.index, e.subindex)


#: the stack's own layout: RxPDO 0x1600 and TxPDO 0x1A00 of drivers.cia402.pdo
BUILTIN_LAYOUT = AxisLayout(
    rx=tuple(WireEntry(e.index, e.subindex, e.bit_length) for e in RXPDO_MAPPING),
    tx=tuple(WireEntry(e.index, e.subindex, e.bit_length) for e in TXPDO_MAPPING),
    rx_pdos=(RXPDO_INDEX,),
    tx_pdos=(TXPDO_INDEX,),
)


def _byte_pairs(
    entries: Sequence[WireEntry], dtype: np.dtype, axis: int = 0
) -> list[tuple[int, int]]:
    """(wire byte, record byte) of every byte of a known object of device axis ``axis``,
    wire order."""
    out = []
    off = 0
    for e in entries:
        size = e.bits // 8
        found = _split(e)
        if found is not None and found[1] == axis:
            field = OBJECT_FIELDS[(found[0], e.subindex)]
            rec = dtype.fields[field][1]  # type: ignore[index]
            out.extend((off + k, rec + k) for k in range(size))
        off += size
    return out


class WireImage:
    """The wire bytes of the drive devices and the tables between them and the n canonical
    records (one per axis the stack runs).

    ``layouts``: one :class:`AxisLayout` per device (checked), in bus order. ``serve``: per
    canonical axis, (device, CiA-402 axis of that device); default: axis i is axis 0 of
    device i (one axis per device). A multi-axis device's axis k has its objects at
    0x6000 + 0x800·k in its PDOs. ``rx_out`` / ``tx_in``: the wire buffers (uint8, all devices
    end to end; device d at ``rx_offsets[d]`` / ``tx_offsets[d]``). :attr:`present`:
    canonical field name -> bool (n,) whether that axis's drive maps the object.
    """

    def __init__(
        self,
        layouts: Sequence[AxisLayout],
        names: Sequence[str] | None = None,
        serve: Sequence[tuple[int, int]] | None = None,
    ):
        serve = [(i, 0) for i in range(len(layouts))] if serve is None else list(serve)
        n = len(serve)
        names = list(names) if names else [f"axis{i}" for i in range(n)]
        self.n = n
        #: (device, device axis) per canonical axis
        self.serve = tuple((int(d), int(k)) for d, k in serve)
        #: the device of each canonical axis, (n,)
        self.device_of = np.array([d for d, _k in self.serve], dtype=np.intp)
        checked = []
        for d, lay in enumerate(layouts):
            mine = [i for i, (dev, _k) in enumerate(self.serve) if dev == d]
            if not mine:
                raise LayoutError(f"device {d} serves no axis")
            who = f"axis {mine[0]} ({names[mine[0]]})"
            if len(mine) > 1:
                who = "axes " + ", ".join(f"{i} ({names[i]})" for i in mine)
            checked.append(lay.check(who, sorted({self.serve[i][1] for i in mine})))
        self.layouts = tuple(checked)
        rx_sizes = [lay.rx_size for lay in layouts]
        tx_sizes = [lay.tx_size for lay in layouts]
        self.rx_offsets = np.concatenate(([0], np.cumsum(rx_sizes))).astype(np.intp)
        self.tx_offsets = np.concatenate(([0], np.cumsum(tx_sizes))).astype(np.intp)
        rx_total, tx_total = int(self.rx_offsets[-1]), int(self.tx_offsets[-1])
        #: the outputs of every drive, end to end [byte]
        self.rx_out = np.zeros(rx_total, dtype=np.uint8)
        # inputs of every drive, then one defaults record per axis (absent fields' values)
        self._tx_ext = np.zeros(tx_total + n * TXPDO_SIZE, dtype=np.uint8)
        #: the inputs of every drive, end to end [byte]
        self.tx_in = self._tx_ext[:tx_total]
        #: per-axis values of TxPDO fields a drive does not report (structured view)
        self.defaults = self._tx_ext[tx_total:].view(TXPDO_DTYPE)
        self.present: dict[str, np.ndarray] = {}
        for dtype, direction in ((RXPDO_DTYPE, "rx"), (TXPDO_DTYPE, "tx")):
            for f in dtype.names or ():
                self.present[f] = np.array(
                    [f in layouts[d].fields(direction, k) for d, k in self.serve], dtype=bool
                )

        zero = n * RXPDO_SIZE  # the zero byte past the canonical RxPDO (see encode_rx)
        enc = np.full(rx_total, zero, dtype=np.intp)
        dec = np.empty(n * TXPDO_SIZE, dtype=np.intp)
        drx_w, drx_r, dtx = [], [], np.full(tx_total, n * TXPDO_SIZE, dtype=np.intp)
        for i, (d, k) in enumerate(self.serve):
            lay = layouts[d]
            ro, to = int(self.rx_offsets[d]), int(self.tx_offsets[d])
            for w, r in _byte_pairs(lay.rx, RXPDO_DTYPE, k):
                enc[ro + w] = i * RXPDO_SIZE + r
                drx_w.append(ro + w)
                drx_r.append(i * RXPDO_SIZE + r)
            # absent TxPDO bytes: this axis's defaults record
            dec[i * TXPDO_SIZE : (i + 1) * TXPDO_SIZE] = (
                tx_total + i * TXPDO_SIZE + np.arange(TXPDO_SIZE)
            )
            for w, r in _byte_pairs(lay.tx, TXPDO_DTYPE, k):
                dec[i * TXPDO_SIZE + r] = to + w
                dtx[to + w] = i * TXPDO_SIZE + r
        self._enc = enc
        self._dec = dec
        self._drx_wire = np.array(drx_w, dtype=np.intp)
        self._drx_rec = np.array(drx_r, dtype=np.intp)
        self._drx_tmp = np.zeros(len(drx_w), dtype=np.uint8)
        self._dtx = dtx
        self._rx_src = np.zeros(n * RXPDO_SIZE + 1, dtype=np.uint8)
        self._drive_tx_src = np.zeros(n * TXPDO_SIZE + 1, dtype=np.uint8)
        self._adapter: Any = None
        self._scaled: Any = None
        #: True when every axis runs the built-in layout (the wire IS the canonical image)
        self.builtin = self.serve == tuple((i, 0) for i in range(len(layouts))) and all(
            lay.rx == BUILTIN_LAYOUT.rx and lay.tx == BUILTIN_LAYOUT.tx for lay in layouts
        )
        #: number of devices
        self.n_devices = len(layouts)

    # ----------------------------------------------------------- sizes and info

    def rx_size(self, device: int) -> int:
        """Output bytes of ``device`` (= axis ``device`` with one axis per device)."""
        return int(self.rx_offsets[device + 1] - self.rx_offsets[device])

    def tx_size(self, device: int) -> int:
        """Input bytes of ``device``."""
        return int(self.tx_offsets[device + 1] - self.tx_offsets[device])

    def rx_slice(self, device: int) -> np.ndarray:
        """View of ``device``'s outputs in :attr:`rx_out`."""
        return self.rx_out[self.rx_offsets[device] : self.rx_offsets[device + 1]]

    def tx_slice(self, device: int) -> np.ndarray:
        """View of ``device``'s inputs in :attr:`tx_in`."""
        return self.tx_in[self.tx_offsets[device] : self.tx_offsets[device + 1]]

    def set_default(self, axis: int, field: str, value: int) -> None:
        """The value canonical TxPDO ``field`` of ``axis`` reads when its drive does not map
        the object (e.g. the mode display after the mode was set and read back by SDO)."""
        self.defaults[field][axis] = value

    # --------------------------------------------------------- master side (hot)

    def bind_master(self, rx: np.ndarray, tx: np.ndarray) -> None:
        """Use the canonical images ``rx`` (RXPDO_DTYPE) and ``tx`` (TXPDO_DTYPE), shape
        (n,), of a transport for :meth:`encode_rx` and :meth:`decode_tx`."""
        self._rx_flat = rx.view(np.uint8).reshape(-1)
        self._tx_flat = tx.view(np.uint8).reshape(-1)
        # the canonical RxPDO is copied into a buffer with one zero byte after it, which
        # padding and unused objects gather from: two calls, both without allocation
        self._rx_head = self._rx_src[: self._rx_flat.size]
        #: the copy as records (what an adapter changes) and the master's TxPDO it reads
        self._rx_copy = self._rx_head.view(RXPDO_DTYPE)
        self._tx_rec = tx

    def set_adapter(self, adapter: Any) -> None:
        """Run ``adapter.apply(rx_copy, tx)`` (:class:`drivers.cia402.csp_adapter.CspAdapter`)
        on the copy of the canonical RxPDO each :meth:`encode_rx` encodes (ip / pv axes);
        None or an adapter without such axes: nothing runs. Call after :meth:`bind_master`."""
        self._adapter = adapter if adapter is not None and adapter.active else None
        #: the adapter when some drive reports velocities in its own unit (rpm)
        scaled = self._adapter is not None and bool(self._adapter.scaled.any())
        self._scaled = self._adapter if scaled else None

    @property
    def adapter(self) -> Any:
        """The adapter set with :meth:`set_adapter` (None: every axis takes CSP as it is)."""
        return self._adapter

    def adapt_rx(self) -> np.ndarray:
        """The canonical RxPDO's bytes as the drives take them (uint8, n records): after the
        adapter (a copy) when one is set, else the record itself. For an in-process bus that
        copies records, not wire bytes. No allocation."""
        if self._adapter is None:
            return self._rx_flat
        np.copyto(self._rx_head, self._rx_flat)
        self._adapter.apply(self._rx_copy, self._tx_rec)
        return self._rx_head

    def encode_rx(self) -> None:
        """Canonical RxPDO -> :attr:`rx_out` (every axis, its own layout; ip / pv axes
        through the adapter, see :meth:`set_adapter`). No allocation."""
        np.copyto(self._rx_head, self._rx_flat)
        if self._adapter is not None:
            self._adapter.apply(self._rx_copy, self._tx_rec)
        self._rx_src.take(self._enc, out=self.rx_out, mode="clip")

    def decode_tx(self) -> None:
        """:attr:`tx_in` -> canonical TxPDO; fields a drive does not map read its default.
        No allocation."""
        self._tx_ext.take(self._dec, out=self._tx_flat, mode="clip")
        if self._scaled is not None:
            self._scaled.decode(self._tx_rec)

    def decode_units(self) -> None:
        """Velocities reported in a drive's own unit (rpm) -> counts/s in the canonical
        TxPDO (what :meth:`decode_tx` does last; an in-process bus that copies records
        calls it itself). No allocation."""
        if self._scaled is not None:
            self._scaled.decode(self._tx_rec)

    def mapped_bytes(self) -> tuple[np.ndarray, np.ndarray]:
        """bool masks over the n canonical RxPDO / TxPDO records' bytes: True where the
        axis's drive maps the field (an in-process bus copies just those, in place)."""
        rx = np.zeros(self.n * RXPDO_SIZE, dtype=bool)
        tx = np.zeros(self.n * TXPDO_SIZE, dtype=bool)
        rx[self._drx_rec] = True
        tx[self._dtx[self._dtx < self.n * TXPDO_SIZE]] = True
        return rx, tx

    # ------------------------------------------------------------ drive side (sim)

    def drive_rx(self, rx: np.ndarray) -> None:
        """:attr:`rx_out` -> a drive-side canonical RxPDO ``rx`` (n,): only the bytes each
        drive maps; the rest keep their values."""
        flat = rx.view(np.uint8).reshape(-1)
        self.rx_out.take(self._drx_wire, out=self._drx_tmp, mode="clip")
        flat[self._drx_rec] = self._drx_tmp

    def drive_tx(self, tx: np.ndarray) -> None:
        """A drive-side canonical TxPDO ``tx`` (n,) -> :attr:`tx_in` (padding zero)."""
        head = self._drive_tx_src[: tx.nbytes]
        np.copyto(head, tx.view(np.uint8).reshape(-1))
        self._drive_tx_src.take(self._dtx, out=self.tx_in, mode="clip")
