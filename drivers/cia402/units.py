"""Raw CiA 402 process values <-> SI at the joint side, per axis, vectorised.

Raw units (never leave drivers/):
- position 0x6064/0x607A: motor encoder counts (``counts_per_rev`` per motor revolution);
- velocity 0x606C/0x60FF: motor encoder counts per second (a drive in rpm: the scalar
  helpers below take its ``unit``, the cyclic stream is scaled by
  :mod:`drivers.cia402.csp_adapter`);
- torque 0x6077/0x6071/0x60B2: per mille of the rated motor torque 0x6076 [mN·m];
- current 0x6078: per mille of the rated motor current 0x6075 [mA].

SI (joint side): q [rad], qd [rad/s], tau [N·m] (motor torque times the gear ratio),
current [A] (motor current, signed in the joint's sense).

  q   = direction · (counts - zero_offset) · 2π / (counts_per_rev · gear_ratio)
  tau = direction · permille / 1000 · rated_torque[mN·m] / 1000 · gear_ratio
  I   = direction · permille / 1000 · rated_current[mA] / 1000

All conversions write into preallocated outputs; ``to_raw`` methods round to the nearest
integer and saturate at the raw type's range.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

TWO_PI = 2.0 * np.pi
_I32 = (float(np.iinfo(np.int32).min), float(np.iinfo(np.int32).max))
_I16 = (float(np.iinfo(np.int16).min), float(np.iinfo(np.int16).max))


@dataclass(frozen=True)
class AxisScaling:
    """Scaling data of one drive axis.

    counts_per_rev: encoder counts per MOTOR revolution (0x608F:1 / 0x608F:2).
    gear_ratio: motor revolutions per joint revolution (0x6091:1 / 0x6091:2), > 0.
    direction: +1 or -1, sign of joint motion for positive motor motion.
    zero_offset: encoder count at joint angle 0.
    rated_torque: 0x6076, rated MOTOR torque [mN·m].
    rated_current: 0x6075, rated motor current [mA].
    torque_constant: motor torque constant [N·m/A] (motor side).
    """

    counts_per_rev: int
    gear_ratio: float
    direction: int = 1
    zero_offset: int = 0
    rated_torque: float = 1000.0
    rated_current: float = 1000.0
    torque_constant: float = 1.0

    @classmethod
    def from_config(cls, d: Any) -> AxisScaling:
        """From a :class:`hofto_hw.config.drives.DriveConfig` (or any object with its fields)."""
        return cls(
            counts_per_rev=int(d.counts_per_rev),
            gear_ratio=float(d.gear_ratio),
            direction=int(d.direction),
            zero_offset=int(d.zero_offset),
            rated_torque=float(d.rated_torque),
            rated_current=float(d.rated_current),
            torque_constant=float(d.torque_constant),
        )

    def __post_init__(self) -> None:
        if self.counts_per_rev <= 0:
            raise ValueError(f"counts_per_rev must be > 0 (got {self.counts_per_rev})")
        if self.gear_ratio <= 0:
            raise ValueError(f"gear_ratio must be > 0 (got {self.gear_ratio})")
        if self.direction not in (1, -1):
            raise ValueError(f"direction must be +1 or -1 (got {self.direction})")
        for name in ("rated_torque", "rated_current", "torque_constant"):
            if getattr(self, name) <= 0:
                raise ValueError(f"{name} must be > 0 (got {getattr(self, name)})")


class Scaling:
    """Vectorised raw <-> SI conversions for n axes (arrays of shape (n,)).

    Every method takes an input array and a preallocated ``out`` and returns ``out``; no
    method allocates after construction.
    """

    def __init__(self, axes: Sequence[AxisScaling]) -> None:
        if not axes:
            raise ValueError("Scaling needs at least one axis")
        self.axes = tuple(axes)
        n = len(axes)
        self.n = n
        f = np.array
        cpr = f([a.counts_per_rev for a in axes], dtype=np.float64)
        gear = f([a.gear_ratio for a in axes], dtype=np.float64)
        sgn = f([a.direction for a in axes], dtype=np.float64)
        self.gear_ratio = gear
        self.direction = sgn
        self.zero_offset = f([a.zero_offset for a in axes], dtype=np.float64)
        self.rated_torque = f([a.rated_torque for a in axes], dtype=np.float64)  # mN·m
        self.rated_current = f([a.rated_current for a in axes], dtype=np.float64)  # mA
        self.torque_constant = f([a.torque_constant for a in axes], dtype=np.float64)
        #: rad (joint) per count
        self.rad_per_count = sgn * TWO_PI / (cpr * gear)
        self.count_per_rad = 1.0 / self.rad_per_count
        #: N·m (joint) per per-mille
        self.nm_per_permille = sgn * self.rated_torque * 1e-6 * gear
        self.permille_per_nm = 1.0 / self.nm_per_permille
        #: A per per-mille
        self.amp_per_permille = sgn * self.rated_current * 1e-6
        self.permille_per_amp = 1.0 / self.amp_per_permille
        self._tmp = np.empty(n, dtype=np.float64)

    # ---------------------------------------------------------------- raw -> SI

    def position_to_si(self, counts: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Encoder counts (n,) -> joint angle q [rad] (n,)."""
        np.subtract(counts, self.zero_offset, out=out)
        np.multiply(out, self.rad_per_count, out=out)
        return out

    def velocity_to_si(self, counts_per_s: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Motor counts/s (n,) -> joint velocity qd [rad/s] (n,)."""
        np.multiply(counts_per_s, self.rad_per_count, out=out)
        return out

    def torque_to_si(self, permille: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Per mille of rated motor torque (n,) -> joint torque tau [N·m] (n,)."""
        np.multiply(permille, self.nm_per_permille, out=out)
        return out

    def current_to_si(self, permille: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Per mille of rated current (n,) -> motor current [A] (n,), joint sense."""
        np.multiply(permille, self.amp_per_permille, out=out)
        return out

    def current_to_torque(self, current: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Motor current [A] (n,) -> joint torque [N·m] (n,) through kt and the gear."""
        np.multiply(current, self.torque_constant, out=out)
        np.multiply(out, self.gear_ratio, out=out)
        return out

    # ---------------------------------------------------------------- SI -> raw

    def _store(self, out: np.ndarray, lim: tuple[float, float]) -> np.ndarray:
        np.rint(self._tmp, out=self._tmp)
        np.clip(self._tmp, lim[0], lim[1], out=self._tmp)
        np.copyto(out, self._tmp, casting="unsafe")
        return out

    def position_to_raw(self, q: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Joint angle q [rad] (n,) -> encoder counts, written into int32 ``out`` (n,)."""
        np.multiply(q, self.count_per_rad, out=self._tmp)
        np.add(self._tmp, self.zero_offset, out=self._tmp)
        return self._store(out, _I32)

    def velocity_to_raw(self, qd: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Joint velocity [rad/s] (n,) -> motor counts/s into int32 ``out`` (n,)."""
        np.multiply(qd, self.count_per_rad, out=self._tmp)
        return self._store(out, _I32)

    def torque_to_raw(self, tau: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Joint torque [N·m] (n,) -> per mille of rated motor torque into int16 ``out``."""
        np.multiply(tau, self.permille_per_nm, out=self._tmp)
        return self._store(out, _I16)

    def current_to_raw(self, current: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Motor current [A] (n,) -> per mille of rated current into int16 ``out`` (n,)."""
        np.multiply(current, self.permille_per_amp, out=self._tmp)
        return self._store(out, _I16)

    # ---------------------------------------------------- scalar helpers (setup only)

    def torque_limit_permille(self, axis: int, tau_max: float) -> int:
        """Joint torque limit [N·m] -> 0x6072 max torque [per mille], u16."""
        return int(min(65535, max(0, round(abs(tau_max * self.permille_per_nm[axis])))))

    def speed_to_raw(self, axis: int, qd: float, unit: float = 1.0) -> int:
        """Joint speed [rad/s] -> motor counts/s (e.g. homing speeds 0x6099), or the drive's
        own unit of ``unit`` counts/s (rpm: 0x608F / 60), magnitude, u32."""
        return int(min(2**32 - 1, round(abs(qd * self.count_per_rad[axis] / unit))))

    def acceleration_to_raw(self, axis: int, qdd: float, unit: float = 1.0) -> int:
        """Joint acceleration [rad/s²] -> motor counts/s² (0x6085 quick-stop deceleration),
        or the drive's own unit of ``unit`` counts/s² (e.g. rpm/s: 0x608F / 60), u32."""
        return int(min(2**32 - 1, round(abs(qdd * self.count_per_rad[axis] / unit))))

    def angle_to_counts(self, axis: int, angle: float) -> int:
        """Joint angle DIFFERENCE [rad] -> counts (magnitude), e.g. following-error window."""
        return int(min(2**32 - 1, round(abs(angle * self.count_per_rad[axis]))))
