"""The one PDO layout every transport and emulator shares.

RxPDO 0x1600 (master -> drive, 15 bytes) and TxPDO 0x1A00 (drive -> master, 21 bytes) as
packed little-endian numpy structured dtypes. A transport owns ``rx`` and ``tx`` arrays of
shape (n_axes,) with these dtypes; one axis is one record, so the six drives are read and
written with a handful of vector operations on field views (e.g. ``tx["position"]``).

The mapping is also given as data (:data:`RXPDO_MAPPING`, :data:`TXPDO_MAPPING`): masters
write it into 0x1600/0x1A00 by SDO, emulators parse what was written with
:func:`parse_mapping_value` and :func:`layout_dtype`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

RXPDO_INDEX = 0x1600
TXPDO_INDEX = 0x1A00
#: Sync-manager PDO assignment objects (EtherCAT: SM2 outputs, SM3 inputs).
RXPDO_ASSIGN_INDEX = 0x1C12
TXPDO_ASSIGN_INDEX = 0x1C13


class PdoEntry(NamedTuple):
    """One mapped object: CiA 301 mapping entry plus the process-image field it fills."""

    index: int
    subindex: int
    bit_length: int
    field: str


#: RxPDO 0x1600, in process-image order.
RXPDO_MAPPING: tuple[PdoEntry, ...] = (
    PdoEntry(0x6040, 0, 16, "controlword"),
    PdoEntry(0x6060, 0, 8, "mode"),
    PdoEntry(0x607A, 0, 32, "target_position"),
    PdoEntry(0x60FF, 0, 32, "target_velocity"),
    PdoEntry(0x6071, 0, 16, "target_torque"),
    PdoEntry(0x60B2, 0, 16, "torque_offset"),
)

#: TxPDO 0x1A00, in process-image order.
TXPDO_MAPPING: tuple[PdoEntry, ...] = (
    PdoEntry(0x6041, 0, 16, "statusword"),
    PdoEntry(0x6061, 0, 8, "mode_display"),
    PdoEntry(0x6064, 0, 32, "position"),
    PdoEntry(0x606C, 0, 32, "velocity"),
    PdoEntry(0x6077, 0, 16, "torque"),
    PdoEntry(0x6078, 0, 16, "current"),
    PdoEntry(0x603F, 0, 16, "error_code"),
    PdoEntry(0x60FD, 0, 32, "digital_inputs"),
)

#: numpy type of every object that may appear in a PDO (CiA 402 data types).
OBJECT_TYPES: dict[tuple[int, int], str] = {
    (0x6040, 0): "<u2",
    (0x6060, 0): "i1",
    (0x607A, 0): "<i4",
    (0x60FF, 0): "<i4",
    (0x6071, 0): "<i2",
    (0x60B2, 0): "<i2",
    (0x6041, 0): "<u2",
    (0x6061, 0): "i1",
    (0x6064, 0): "<i4",
    (0x606C, 0): "<i4",
    (0x6077, 0): "<i2",
    (0x6078, 0): "<i2",
    (0x603F, 0): "<u2",
    (0x60FD, 0): "<u4",
    (0x60C1, 1): "<i4",
}

#: objects that carry a canonical field on the wire besides the built-in layout's own:
#: 0x60C1:01, the first interpolation data record entry (X1), is the position target of
#: interpolated position mode (ip); the loop's CSP target goes there on an ip drive
EXTRA_FIELDS: dict[tuple[int, int], str] = {(0x60C1, 1): "target_position"}

#: process-image field name of every PDO-mappable object.
OBJECT_FIELDS: dict[tuple[int, int], str] = {
    (e.index, e.subindex): e.field for e in RXPDO_MAPPING + TXPDO_MAPPING
} | EXTRA_FIELDS


def layout_dtype(entries: tuple[PdoEntry, ...] | list[PdoEntry]) -> np.dtype:
    """Packed little-endian structured dtype for a mapping (fields in mapping order).

    Raises ``ValueError`` naming the object when it is not PDO-mappable or its bit length
    does not match its data type.
    """
    fields = []
    for e in entries:
        key = (e.index, e.subindex)
        if key not in OBJECT_TYPES:
            raise ValueError(f"object 0x{e.index:04X}:{e.subindex:02X} is not PDO-mappable")
        t = np.dtype(OBJECT_TYPES[key])
        if t.itemsize * 8 != e.bit_length:
            raise ValueError(
                f"object 0x{e.index:04X}:{e.subindex:02X} is {t.itemsize * 8} bits, "
                f"mapping says {e.bit_length}"
            )
        fields.append((e.field, t))
    return np.dtype(fields)  # list form: packed, no padding


RXPDO_DTYPE: np.dtype = layout_dtype(RXPDO_MAPPING)
TXPDO_DTYPE: np.dtype = layout_dtype(TXPDO_MAPPING)
RXPDO_SIZE: int = RXPDO_DTYPE.itemsize  # 15 bytes
TXPDO_SIZE: int = TXPDO_DTYPE.itemsize  # 21 bytes


def mapping_value(entry: PdoEntry) -> int:
    """The u32 written to a mapping sub-index: index << 16 | subindex << 8 | bit length."""
    return (entry.index << 16) | (entry.subindex << 8) | entry.bit_length


def parse_mapping_value(value: int) -> PdoEntry:
    """Inverse of :func:`mapping_value`; ``field`` is the process-image name or ``""``."""
    index = (value >> 16) & 0xFFFF
    sub = (value >> 8) & 0xFF
    return PdoEntry(index, sub, value & 0xFF, OBJECT_FIELDS.get((index, sub), ""))


def new_rx(n_axes: int) -> np.ndarray:
    """Zeroed RxPDO image, shape (n_axes,), dtype :data:`RXPDO_DTYPE`."""
    return np.zeros(n_axes, dtype=RXPDO_DTYPE)


def new_tx(n_axes: int) -> np.ndarray:
    """Zeroed TxPDO image, shape (n_axes,), dtype :data:`TXPDO_DTYPE`."""
    return np.zeros(n_axes, dtype=TXPDO_DTYPE)


class ImageFields:
    """Mixin: named views of the process-image fields, bound by :meth:`_bind_image`.

    For the classes that fill and decode the images every cycle (the drive layer and the
    emulated drives). Each attribute is a field view of shape (n,) into the records, so
    writes go straight into ``rx``/``tx`` and nothing is allocated in the cycle.
    """

    _rx_cw: np.ndarray  # 0x6040 controlword, uint16
    _rx_mode: np.ndarray  # 0x6060 mode of operation, int8
    _rx_pos: np.ndarray  # 0x607A target position [counts], int32
    _rx_vel: np.ndarray  # 0x60FF target velocity [counts/s], int32
    _rx_tau: np.ndarray  # 0x6071 target torque [per mille], int16
    _rx_off: np.ndarray  # 0x60B2 torque offset [per mille], int16
    _tx_sw: np.ndarray  # 0x6041 statusword, uint16
    _tx_mode: np.ndarray  # 0x6061 mode display, int8
    _tx_pos: np.ndarray  # 0x6064 position [counts], int32
    _tx_vel: np.ndarray  # 0x606C velocity [counts/s], int32
    _tx_tau: np.ndarray  # 0x6077 torque [per mille], int16
    _tx_cur: np.ndarray  # 0x6078 current [per mille], int16
    _tx_err: np.ndarray  # 0x603F error code, uint16
    _tx_din: np.ndarray  # 0x60FD digital inputs, uint32

    def _bind_image(self, rx: np.ndarray, tx: np.ndarray) -> None:
        """Point the views at ``rx`` (RXPDO_DTYPE) and ``tx`` (TXPDO_DTYPE), shape (n,)."""
        self._rx_cw = rx["controlword"]
        self._rx_mode = rx["mode"]
        self._rx_pos = rx["target_position"]
        self._rx_vel = rx["target_velocity"]
        self._rx_tau = rx["target_torque"]
        self._rx_off = rx["torque_offset"]
        self._tx_sw = tx["statusword"]
        self._tx_mode = tx["mode_display"]
        self._tx_pos = tx["position"]
        self._tx_vel = tx["velocity"]
        self._tx_tau = tx["torque"]
        self._tx_cur = tx["current"]
        self._tx_err = tx["error_code"]
        self._tx_din = tx["digital_inputs"]
