"""Signals a drive does not report, computed from those it does (a profile's ``fallbacks``).

A transport whose drives run profiles keeps one :class:`DerivedSignals` over its canonical
TxPDO image and calls :meth:`DerivedSignals.apply` right after each fresh decode, before the
drive group reads the image:

- ``torque: current`` (no 0x6077, 0x6078 mapped): the canonical torque field of that axis
  carries the raw current (per mille of rated current); the drive group reads it with the
  scale ``amp_per_permille x torque_constant x gear_ratio`` (:func:`torque_scale`): joint
  torque [N·m] = motor current [A] x the axis's torque constant from the config [N·m/A] x
  its gear ratio, in SI (no second rounding in raw units);
- ``velocity: position_derivative`` (no 0x606C): the canonical velocity field [counts/s] is
  the position difference over the bus's sample interval (``sample_dt``, else the cycle),
  low-pass filtered (first order, :data:`VELOCITY_CUTOFF_HZ`); the difference is taken in
  int32 so an encoder wrap-around gives the right step.

Preallocated buffers, full-width numpy calls with ``out=``/``where=``: nothing is allocated
per cycle.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

#: cut-off of the first-order low-pass on the position difference [Hz]: at a 1 kHz loop the
#: filter's time constant (1.06 ms) is about one cycle, so the estimate lags the true
#: velocity by ~1.5 cycles (half a sample for the difference, one for the filter) and the
#: count quantisation (1 count per cycle = 1000 counts/s) is averaged over ~2 cycles
VELOCITY_CUTOFF_HZ = 150.0


def derived_masks(profiles: Sequence[Any | None]) -> tuple[np.ndarray, np.ndarray]:
    """bool (n,) per axis: (torque from current, velocity from position) as each axis's
    profile (None: the built-in layout, nothing derived) says."""
    tau = np.array(
        [p is not None and p.fallbacks.get("torque") == "current" for p in profiles], dtype=bool
    )
    vel = np.array(
        [p is not None and p.fallbacks.get("velocity") == "position_derivative" for p in profiles],
        dtype=bool,
    )
    return tau, vel


def torque_scale(scaling: Any, from_current: np.ndarray) -> np.ndarray:
    """N·m (joint) per raw unit of the canonical torque field, (n,): the drive's
    ``nm_per_permille``, or for axes whose torque is their current (``from_current``)
    ``amp_per_permille x torque_constant x gear_ratio``."""
    out = np.array(scaling.nm_per_permille, dtype=np.float64)
    from_i = scaling.amp_per_permille * scaling.torque_constant * scaling.gear_ratio
    np.copyto(out, from_i, where=from_current)
    return out


class DerivedSignals:
    """Fills the canonical TxPDO fields of ``tx`` (TXPDO_DTYPE, (n,)) some drives do not
    report, from those they do (see module docstring). ``torque_from_current`` and
    ``velocity_from_position``: bool (n,) per axis; ``cycle_time`` [s]: the interval used
    when the bus does not know its sample interval."""

    def __init__(
        self,
        tx: np.ndarray,
        torque_from_current: np.ndarray,
        velocity_from_position: np.ndarray,
        cycle_time: float,
        cutoff_hz: float = VELOCITY_CUTOFF_HZ,
    ) -> None:
        n = tx.shape[0]
        self.tau_mask = np.asarray(torque_from_current, dtype=bool).copy()
        self.vel_mask = np.asarray(velocity_from_position, dtype=bool).copy()
        self.any_torque = bool(self.tau_mask.any())
        self.any_velocity = bool(self.vel_mask.any())
        self.cycle_time = float(cycle_time)
        self.cutoff_hz = float(cutoff_hz)
        self._tau = tx["torque"]
        self._cur = tx["current"]
        self._pos = tx["position"]
        self._vel = tx["velocity"]
        self._prev = np.zeros(n, dtype=np.int32)
        self._step = np.zeros(n, dtype=np.int32)
        self._rate = np.zeros(n)
        #: the filtered velocity [counts/s], (n,) (0 on axes that report theirs)
        self.velocity = np.zeros(n)
        self._started = False
        self._dt = -1.0
        self._keep = np.zeros(n)
        self._gain = np.zeros(n)

    def reset(self) -> None:
        """Forget the previous position (after a restart of the exchange)."""
        self._started = False
        self.velocity.fill(0.0)

    def apply(self, sample_dt: float) -> None:
        """Fill the derived fields after a fresh decode. ``sample_dt`` [s]: the transport's
        (> 0: the drives' samples moved this much; 0: unknown, one cycle is assumed; < 0: no
        new sample, the velocity is held)."""
        if self.any_torque:
            np.copyto(self._tau, self._cur, where=self.tau_mask)
        if not self.any_velocity:
            return
        if not self._started:
            np.copyto(self._prev, self._pos)
            self._started = True
        elif sample_dt >= 0.0:
            dt = sample_dt if sample_dt > 0.0 else self.cycle_time
            if dt != self._dt:  # the filter's coefficients for this interval (on a change)
                self._dt = dt
                alpha = 1.0 - math.exp(-2.0 * math.pi * self.cutoff_hz * dt)
                self._keep.fill(1.0 - alpha)
                self._gain.fill(alpha / dt)
            np.subtract(self._pos, self._prev, out=self._step)  # int32: wraps like the encoder
            np.copyto(self._prev, self._pos)
            np.copyto(self._rate, self._step)
            # v += alpha·(step/dt - v)  as  v = (1 - alpha)·v + (alpha/dt)·step; coefficient
            # arrays, not Python floats: a scalar operand costs a conversion per call
            np.multiply(self._rate, self._gain, out=self._rate)
            np.multiply(self.velocity, self._keep, out=self.velocity)
            np.add(self.velocity, self._rate, out=self.velocity)
        np.rint(self.velocity, out=self._rate)
        np.copyto(self._vel, self._rate, where=self.vel_mask, casting="unsafe")
