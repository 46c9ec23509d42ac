"""The drive group's raw <-> SI conversions of its hot path, its one implementation: compiled
(numba) or, for the ``python`` backend, the same functions' Python source run by the
interpreter (:func:`hofto_hw.jit.compiled_or_python`).

One drive-group read is five conversions of six-element arrays (position, velocity, torque,
current, state); done as ~8 numpy calls the time goes to the ~0.5-1 µs each call costs. Here
a read, and a CSP/CSV command with its torque offset, is one call each. The numpy reference
of the same arithmetic (:mod:`drivers.cia402.units`' vector conversions) lives in
tests/drivers/cia402/reference.py; tests/drivers/cia402/test_cia402_kernels.py checks both
the compiled and the Python source agree with it exactly on random raw images and commands,
saturation and NaN included.

Few arguments: a compiled call pays per argument it unboxes (~0.1 µs alone, more with cold
caches; tools/bench_kernel_args.py), and the process image's field views are strided views of
a packed record array, one argument each. So the kernels take the images as their raw bytes
(one contiguous uint8 view each; the fields are decoded at the byte offsets of the one PDO
layout, :mod:`drivers.cia402.pdo`, little-endian as the layout says) and the drive group's
SI values and constant scale rows as the rows of one float64 workspace (:data:`SI_ROWS`).

The backend conventions are those of :mod:`hofto_hw.jit` (its availability,
``HOFTO_HW_NO_NUMBA``, compile options and warm-up are reused, so one switch decides whether
compiled code runs anywhere): ``python`` (the Python source), ``numba``, ``auto``. Kernels write
only into the arrays passed in and never allocate.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable

import numpy as np

from drivers.cia402.pdo import RXPDO_DTYPE, RXPDO_SIZE, TXPDO_DTYPE, TXPDO_SIZE
from drivers.cia402.state_machine import STATE_FROM_STATUS
from hofto_hw.jit import Backend, jit, resolve, warm

try:  # the byte helpers: compiled into the kernels that call them, plain Python otherwise
    from numba.extending import register_jitable as _helper
except Exception:  # numba missing or not importable: the kernels run as Python anyway

    def _helper(fn):  # type: ignore[no-untyped-def]
        return fn


__all__ = [
    "POSITION",
    "SI_ROWS",
    "VELOCITY",
    "WITH_TAU",
    "Backend",
    "command_raw",
    "image_bytes",
    "layout_matches",
    "read_si",
    "ready",
]

#: rows of the drive group's float64 workspace (SI_ROWS, n): the read's outputs q [rad],
#: qd [rad/s], tau [N·m], current [A], then the constant scale rows
Q, QD, TAU, CURRENT = 0, 1, 2, 3
#: zero offset [counts], rad/count, N·m/‰, A/‰, count/rad, ‰/N·m
ZERO, RAD_PER_COUNT, NM_PER_PERMILLE, AMP_PER_PERMILLE, COUNT_PER_RAD, PERMILLE_PER_NM = range(
    4, 10
)
SI_ROWS = 10

#: :func:`command_raw`'s ``what``: the target is a position (CSP) or a velocity (CSV); with
#: WITH_TAU set the torque offset is written too
POSITION, VELOCITY, WITH_TAU = 0, 1, 2

_I32_MIN = float(np.iinfo(np.int32).min)
_I32_MAX = float(np.iinfo(np.int32).max)
_I16_MIN = float(np.iinfo(np.int16).min)
_I16_MAX = float(np.iinfo(np.int16).max)

# The PDO layout and the statusword table as the kernels' compile-time constants, written
# out here: numba bakes globals into the cached machine code and invalidates its cache only
# when this file changes, not when drivers/cia402/pdo.py or state_machine.py do. So they are
# literals here, checked against those modules (:func:`layout_matches`; on a mismatch a drive
# group refuses to be built, and tests/drivers/cia402/test_cia402_kernels.py fails).
_TX = 21  # TxPDO record size [bytes]
_TX_SW, _TX_POS, _TX_VEL, _TX_TAU, _TX_CUR = 0, 3, 7, 11, 13  # u16, i32, i32, i16, i16
_RX = 15  # RxPDO record size [bytes]
_RX_POS, _RX_VEL, _RX_OFF = 3, 7, 13  # i32, i32, i16
_STATE_TABLE = STATE_FROM_STATUS
_STATE_TABLE_SHA256 = "730f61a170b27f65"  # first 16 hex digits of its bytes' SHA-256


def layout_matches() -> bool:
    """True when the literals above are the PDO layout of :mod:`drivers.cia402.pdo` and the
    statusword table of :mod:`drivers.cia402.state_machine` (else the kernels would decode
    another layout than the images have: :func:`ready` answers False and a drive group
    refuses to be built)."""
    tx, rx = TXPDO_DTYPE.fields, RXPDO_DTYPE.fields
    want = (
        (tx, "statusword", "<u2", _TX_SW),
        (tx, "position", "<i4", _TX_POS),
        (tx, "velocity", "<i4", _TX_VEL),
        (tx, "torque", "<i2", _TX_TAU),
        (tx, "current", "<i2", _TX_CUR),
        (rx, "target_position", "<i4", _RX_POS),
        (rx, "target_velocity", "<i4", _RX_VEL),
        (rx, "torque_offset", "<i2", _RX_OFF),
    )
    for fields, name, dtype, offset in want:
        got = fields.get(name)
        if got is None or got[0] != np.dtype(dtype) or got[1] != offset:
            return False
    digest = hashlib.sha256(np.ascontiguousarray(_STATE_TABLE).tobytes()).hexdigest()
    return (
        TXPDO_SIZE == _TX
        and RXPDO_SIZE == _RX
        and _STATE_TABLE.dtype == np.uint8
        and digest[:16] == _STATE_TABLE_SHA256
    )


def image_bytes(image: np.ndarray) -> np.ndarray:
    """The raw bytes of a process image (TXPDO_DTYPE or RXPDO_DTYPE records, shape (n,),
    contiguous) as one uint8 view (n · record size,) sharing its memory."""
    if image.dtype not in (TXPDO_DTYPE, RXPDO_DTYPE) or not image.flags.c_contiguous:
        raise ValueError(f"not a contiguous process image: {image.dtype}")
    return image.view(np.uint8)


@_helper
def _u16(b: np.ndarray, o: int) -> int:
    return np.int64(b[o]) | (np.int64(b[o + 1]) << 8)


@_helper
def _i16(b: np.ndarray, o: int) -> int:
    v = _u16(b, o)
    return v - 65536 if v >= 32768 else v


@_helper
def _i32(b: np.ndarray, o: int) -> int:
    v = _u16(b, o) | (_u16(b, o + 2) << 16)
    return v - 4294967296 if v >= 2147483648 else v


@_helper
def _put(b: np.ndarray, o: int, v: int, size: int) -> None:
    for k in range(size):
        b[o + k] = (v >> (8 * k)) & 0xFF


@jit
def read_si(tx: np.ndarray, w: np.ndarray, states: np.ndarray) -> None:
    """TxPDO bytes ``tx`` (n · 21,) -> SI for every axis: rows Q, QD, TAU, CURRENT of ``w``
    (SI_ROWS, n) from the raw fields and w's scale rows; ``states`` (uint8, n) =
    STATE_FROM_STATUS[statusword & 0x7F]."""
    for i in range(states.shape[0]):
        o = i * _TX
        w[Q, i] = (_i32(tx, o + _TX_POS) - w[ZERO, i]) * w[RAD_PER_COUNT, i]
        w[QD, i] = _i32(tx, o + _TX_VEL) * w[RAD_PER_COUNT, i]
        w[TAU, i] = _i16(tx, o + _TX_TAU) * w[NM_PER_PERMILLE, i]
        w[CURRENT, i] = _i16(tx, o + _TX_CUR) * w[AMP_PER_PERMILLE, i]
        states[i] = _STATE_TABLE[_u16(tx, o + _TX_SW) & 0x7F]


@_helper
def _to_raw(x: float, lo: float, hi: float) -> float:
    """Round half to even and saturate (NaN stays NaN), as np.rint + np.clip."""
    x = np.rint(x)
    if x < lo:
        return lo
    if x > hi:
        return hi
    return x


@jit
def command_raw(
    target: np.ndarray, tau: np.ndarray, rx: np.ndarray, w: np.ndarray, what: int
) -> None:
    """SI -> RxPDO bytes ``rx`` (n · 15,). ``what`` POSITION: target position (int32) =
    rint(target·count/rad + zero), VELOCITY: target velocity = rint(target·count/rad + 0),
    saturated; with WITH_TAU set also the torque offset (int16) = rint(tau·‰/N·m),
    saturated (scale rows of ``w``). A NaN becomes what numpy's cast gives on x86-64 (int32
    minimum; 0 for int16, its low 16 bits): the reference's value."""
    velocity = (what & VELOCITY) != 0
    at = _RX_VEL if velocity else _RX_POS
    for i in range(target.shape[0]):
        zero = 0.0 if velocity else w[ZERO, i]
        v = _to_raw(target[i] * w[COUNT_PER_RAD, i] + zero, _I32_MIN, _I32_MAX)
        _put(rx, i * _RX + at, np.int64(_I32_MIN) if math.isnan(v) else np.int64(v), 4)
        if what & WITH_TAU:
            t = _to_raw(tau[i] * w[PERMILLE_PER_NM, i], _I16_MIN, _I16_MAX)
            _put(rx, i * _RX + _RX_OFF, 0 if math.isnan(t) else np.int64(t), 2)


def ready(backend: Backend, call: Callable[[], object]) -> bool:
    """True when ``backend`` resolves to the compiled kernels and ``call`` (the caller's
    kernels on scratch copies of its own arrays, so the exact signatures compile now,
    outside any loop) succeeds; False means: run the kernels' Python source."""
    if resolve(backend) != "numba" or not layout_matches():
        return False
    return warm(call)
