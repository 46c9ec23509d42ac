"""The monitor's constant parameters as flat arrays, built from either config form.

- ``par`` (L, 6, k, n): per level l, observer row r and joint j: base in the nominal phase,
  base in the acceleration phase, velocity gain kv, acceleration gain ka, reversal margin
  kr, standstill margin ks (units of the threshold formula in safety/collision/__init__.py);
- ``scal`` (:data:`N_SCAL`,): the scalars, indexed by the ``S_*`` constants below;
- ``deciding`` (k,) bool: the rows whose decision counts.

Levels are ordered lowest first: (contact, collision) for the loop's config, (collision,)
for a thresholds file. The last level is always the collision level.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from hofto_hw.config.collision import TERM_LISTS, CollisionConfig, ThresholdTerms

LOGICS = ("any", "all", "mean")  # index = the logic code the kernels take

# scal indices
S_V_REV = 0  # reversal_velocity [rad/s]
S_TAU_A = 1  # time constant of the acceleration low-pass [s]
S_MOVING_TIME = 2
S_REVERSAL_TIME = 3
S_V_STILL = 4  # standstill_velocity [rad/s]
S_STILL_TIME = 5
S_ACCEL_LEVEL = 6  # acceleration-phase level [rad/s²] (inf: never)
S_PHASE_HOLD = 7
S_TRIP_AFTER = 8  # debounce: trip when the time above >= this [s]
S_RELEASE_AFTER = 9
S_RELEASE_RATIO = 10
S_LOGIC = 11  # index into LOGICS
N_SCAL = 12

#: the feature settings that rows built from different thresholds-file monitors must share
SHARED = (
    "reversal_velocity",
    "accel_filter_hz",
    "moving_time",
    "reversal_time",
    "standstill_velocity",
    "standstill_time",
    "debounce_time",
    "release_ratio",
    "release_time",
)


@dataclass(frozen=True)
class MonitorParams:
    """Constant arrays of one monitor (see the module docstring)."""

    levels: tuple[str, ...]
    rows: tuple[str, ...]
    par: np.ndarray
    scal: np.ndarray
    deciding: np.ndarray

    @property
    def logic(self) -> str:
        return LOGICS[int(self.scal[S_LOGIC])]


def _terms(cfg: ThresholdTerms, n: int) -> np.ndarray:
    """(4, n) kv, ka, kr, ks (None = 0)."""
    out = np.zeros((4, n))
    for i, name in enumerate(TERM_LISTS):
        v = getattr(cfg, name)
        if v is not None:
            out[i] = v
    return out


def _scalars(
    cfg: ThresholdTerms,
    debounce: float,
    release: float,
    logic: str,
    accel_level: float = math.inf,
    phase_hold: float = 0.0,
) -> np.ndarray:
    s = np.zeros(N_SCAL)
    s[S_V_REV] = cfg.reversal_velocity
    s[S_TAU_A] = 1.0 / (2.0 * math.pi * cfg.accel_filter_hz)
    s[S_MOVING_TIME] = cfg.moving_time
    s[S_REVERSAL_TIME] = cfg.reversal_time
    s[S_V_STILL] = cfg.standstill_velocity
    s[S_STILL_TIME] = cfg.standstill_time
    s[S_ACCEL_LEVEL] = accel_level
    s[S_PHASE_HOLD] = phase_hold
    # (t >= 0) would hold with zero time above: a tiny floor keeps "0 = trip at once"
    s[S_TRIP_AFTER] = max(debounce - 1e-9, 1e-12)
    s[S_RELEASE_AFTER] = max(release - 1e-9, 1e-12)
    s[S_RELEASE_RATIO] = cfg.release_ratio
    s[S_LOGIC] = LOGICS.index(logic)
    return s


def from_levels_config(cfg: object, rows: Sequence[str]) -> MonitorParams:
    """The loop's ``safety.collision`` (CollisionLevelsConfig): contact and collision levels,
    two phases, the same thresholds for every row; ``rows`` names the estimate rows.

    Raises ValueError when the deciding observers are not among ``rows``."""
    c = cfg  # a CollisionLevelsConfig (hofto_hw.config.safety; typed loosely to keep layers)
    n = c.joints()  # type: ignore[attr-defined]
    k = len(rows)
    choice = c.observer  # type: ignore[attr-defined]
    wanted = ["hofto", "momentum"] if choice == "both" else [choice]
    missing = [w for w in wanted if w not in rows]
    if missing:
        raise ValueError(f"safety.collision.observer needs estimates from {missing}")
    par = np.zeros((2, 6, k, n))
    terms = _terms(c, n)  # type: ignore[arg-type]
    for li, name in enumerate(("contact", "collision")):
        level = getattr(c, name)
        par[li, 0] = level.nominal
        par[li, 1] = level.acceleration
        par[li, 2:] = terms[:, None, :]
    scal = _scalars(
        c,  # type: ignore[arg-type]
        c.debounce_time,  # type: ignore[attr-defined]
        c.release_time,  # type: ignore[attr-defined]
        c.logic,  # type: ignore[attr-defined]
        c.acceleration_phase,  # type: ignore[attr-defined]
        c.phase_hold,  # type: ignore[attr-defined]
    )
    deciding = np.array([r in wanted for r in rows])
    return MonitorParams(("contact", "collision"), tuple(rows), par, scal, deciding)


def from_thresholds(
    monitors: Mapping[str, CollisionConfig],
    deciding: Sequence[str] | None = None,
    logic: str = "any",
) -> MonitorParams:
    """One collision level, one phase, one row per thresholds-file monitor (``{row name:
    CollisionConfig}``, in row order), each with its own thresholds; ``deciding`` rows (all
    when None) combined with ``logic``. The feature filters and debounce settings (:data:`SHARED`)
    must agree between rows (ValueError naming the field otherwise)."""
    if logic not in LOGICS:
        raise ValueError(f"logic must be one of {LOGICS}, got {logic!r}")
    rows = list(monitors)
    if not rows:
        raise ValueError("no monitor rows")
    first = monitors[rows[0]]
    n = first.joints()
    for name in rows[1:]:
        m = monitors[name]
        if m.joints() != n:
            raise ValueError(f"monitor {name!r} has {m.joints()} joints, {rows[0]!r} has {n}")
        for field in SHARED:
            if getattr(m, field) != getattr(first, field):
                raise ValueError(
                    f"monitor {name!r}: {field} = {getattr(m, field)} differs from "
                    f"{rows[0]!r}'s {getattr(first, field)} (rows share it)"
                )
    dec = rows if deciding is None else list(deciding)
    missing = [d for d in dec if d not in rows]
    if missing or not dec:
        raise ValueError(f"deciding rows {missing or dec} are not among the monitors {rows}")
    par = np.zeros((1, 6, len(rows), n))
    for r, name in enumerate(rows):
        m = monitors[name]
        par[0, 0, r] = m.base
        par[0, 1, r] = m.base
        par[0, 2:, r] = _terms(m, n)
    scal = _scalars(first, first.debounce_time, first.release_time, logic)
    return MonitorParams(("collision",), tuple(rows), par, scal, np.array([r in dec for r in rows]))
