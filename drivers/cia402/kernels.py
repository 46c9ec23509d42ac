"""Compiled raw <-> SI conversions of the drive group's hot path (numba), beside the numpy
reference path of :mod:`drivers.cia402.units`.

One drive-group read is five conversions of six-element arrays (position, velocity, torque,
current, state); done as ~8 numpy calls the time goes to the ~0.5-1 µs each call costs. Here
a read, and a CSP/CSV command with its torque offset, is one call each, with the same
arithmetic as the numpy path (tests/drivers/cia402/test_cia402_kernels.py checks both agree
exactly on random raw images and commands, saturation and NaN included).

The backend conventions are those of :mod:`hofto_hw.observers.kernels` (its availability,
``HOFTO_HW_NO_NUMBA``, compile options and warm-up are reused, so one switch decides whether
compiled code runs anywhere): ``numpy`` (the reference), ``numba``, ``auto``. Kernels write
only into the arrays passed in and never allocate.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from hofto_hw.observers.kernels import Backend, jit, resolve, warm

__all__ = ["Backend", "command_raw", "read_si", "ready"]

_I32_MIN = float(np.iinfo(np.int32).min)
_I32_MAX = float(np.iinfo(np.int32).max)
_I16_MIN = float(np.iinfo(np.int16).min)
_I16_MAX = float(np.iinfo(np.int16).max)


@jit
def read_si(
    pos: np.ndarray,
    vel: np.ndarray,
    tau_raw: np.ndarray,
    cur: np.ndarray,
    statusword: np.ndarray,
    zero: np.ndarray,
    scale: np.ndarray,
    state_table: np.ndarray,
    si: np.ndarray,
    states: np.ndarray,
) -> None:
    """TxPDO -> SI for every axis: si rows q [rad], qd [rad/s], tau [N·m], current [A] from
    the raw fields; scale rows rad/count, N·m/‰, A/‰; states = state_table[statusword & 0x7F].
    """
    for i in range(pos.shape[0]):
        si[0, i] = (pos[i] - zero[i]) * scale[0, i]
        si[1, i] = vel[i] * scale[0, i]
        si[2, i] = tau_raw[i] * scale[1, i]
        si[3, i] = cur[i] * scale[2, i]
        states[i] = state_table[statusword[i] & 0x7F]


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
    target: np.ndarray,
    counts_per_unit: np.ndarray,
    zero: np.ndarray,
    out: np.ndarray,
    tau: np.ndarray,
    permille_per_nm: np.ndarray,
    out_tau: np.ndarray,
    with_tau: bool,
) -> None:
    """SI -> RxPDO: out (int32) = rint(target·counts_per_unit + zero), saturated; with_tau:
    out_tau (int16) = rint(tau·permille_per_nm), saturated. A NaN becomes what numpy's cast
    gives on x86-64 (int32 minimum; 0 for int16, its low 16 bits): the reference's value."""
    for i in range(target.shape[0]):
        v = _to_raw(target[i] * counts_per_unit[i] + zero[i], _I32_MIN, _I32_MAX)
        out[i] = _I32_MIN if math.isnan(v) else v
        if with_tau:
            t = _to_raw(tau[i] * permille_per_nm[i], _I16_MIN, _I16_MAX)
            out_tau[i] = 0.0 if math.isnan(t) else t


def ready(backend: Backend, call: Callable[[], object]) -> bool:
    """True when ``backend`` resolves to the compiled kernels and ``call`` (the caller's
    kernels on scratch copies of its own arrays, so the exact signatures compile now,
    outside any loop) succeeds; False means: run the numpy path."""
    if resolve(backend) != "numba":
        return False
    return warm(call)
