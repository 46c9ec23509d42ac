"""Compiled raw <-> SI conversions of the drive group's hot path (numba), beside the numpy
reference path of :mod:`drivers.cia402.units`.

One drive-group read is five conversions of six-element arrays (position, velocity, torque,
current, state); done as ~8 numpy calls the time goes to the ~0.5-1 µs each call costs. Here
a read, and a CSP/CSV command with its torque offset, is one call each, with the same
arithmetic as the numpy path (tests/drivers/cia402/test_cia402_kernels.py checks both agree
exactly on random raw images and commands, saturation and NaN included).

Few arguments: a compiled call pays per argument it unboxes (~0.1 µs alone, more with cold
caches; tools/bench_kernel_args.py), and the process image's field views are strided views of
a packed record array, one argument each. So the kernels take the images as their raw bytes
(one contiguous uint8 view each; the fields are decoded at the byte offsets of the one PDO
layout, :mod:`drivers.cia402.pdo`, little-endian as the layout says) and the drive group's
SI values and constant scale rows as the rows of one float64 workspace (:data:`SI_ROWS`).

The backend conventions are those of :mod:`hofto_hw.observers.kernels` (its availability,
``HOFTO_HW_NO_NUMBA``, compile options and warm-up are reused, so one switch decides whether
compiled code runs anywhere): ``numpy`` (the reference), ``numba``, ``auto``. Kernels write
only into the arrays passed in and never allocate.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from drivers.cia402.pdo import RXPDO_DTYPE, RXPDO_SIZE, TXPDO_DTYPE, TXPDO_SIZE
from drivers.cia402.state_machine import STATE_FROM_STATUS
from hofto_hw.observers.kernels import Backend, jit, resolve, warm

__all__ = [
    "POSITION",
    "SI_ROWS",
    "VELOCITY",
    "WITH_TAU",
    "Backend",
    "command_raw",
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

# byte offsets of the fields in one record (compile-time constants of the kernels)
_TX = TXPDO_SIZE
_TX_SW = TXPDO_DTYPE.fields["statusword"][1]
_TX_POS = TXPDO_DTYPE.fields["position"][1]
_TX_VEL = TXPDO_DTYPE.fields["velocity"][1]
_TX_TAU = TXPDO_DTYPE.fields["torque"][1]
_TX_CUR = TXPDO_DTYPE.fields["current"][1]
_RX = RXPDO_SIZE
_RX_POS = RXPDO_DTYPE.fields["target_position"][1]
_RX_VEL = RXPDO_DTYPE.fields["target_velocity"][1]
_RX_OFF = RXPDO_DTYPE.fields["torque_offset"][1]
_STATE_TABLE = STATE_FROM_STATUS


def image_bytes(image: np.ndarray) -> np.ndarray:
    """The raw bytes of a process image (TXPDO_DTYPE or RXPDO_DTYPE records, shape (n,),
    contiguous) as one uint8 view (n · record size,) sharing its memory."""
    if image.dtype not in (TXPDO_DTYPE, RXPDO_DTYPE) or not image.flags.c_contiguous:
        raise ValueError(f"not a contiguous process image: {image.dtype}")
    return image.view(np.uint8)


@jit
def _u16(b: np.ndarray, o: int) -> int:
    return np.int64(b[o]) | (np.int64(b[o + 1]) << 8)


@jit
def _i16(b: np.ndarray, o: int) -> int:
    v = _u16(b, o)
    return v - 65536 if v >= 32768 else v


@jit
def _i32(b: np.ndarray, o: int) -> int:
    v = _u16(b, o) | (_u16(b, o + 2) << 16)
    return v - 4294967296 if v >= 2147483648 else v


@jit
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


@jit
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
    outside any loop) succeeds; False means: run the numpy path."""
    if resolve(backend) != "numba":
        return False
    return warm(call)
