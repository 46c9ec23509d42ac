"""The tick's own bookkeeping between the safety checks, as one call (numba), and the tick's
glue arithmetic (one definition each, for the reference stages and the fused call).

Each of these is a numpy call or a Python loop over six elements (~1-4 µs each with the
caches cold after the exchange); together they are one compiled call. Backend conventions are
:mod:`hofto_hw.jit`'s; the tick warms the kernel when built and
runs the same source as Python without the compiled path.
tests/hofto_hw/runtime/test_tick_kernels.py checks it against a numpy reference kept there.
"""

from __future__ import annotations

import math

import numpy as np

from drivers.cia402.state_machine import State
from hofto_hw.jit import jit

#: bit of :func:`tick_flags`'s answer: every estimate in ``tau_ext`` is finite
ESTIMATES_FINITE = 1
#: bit of :func:`tick_flags`'s answer: some axis is in one of the ``powered`` states
POWER_ON = 2
#: the power stage is on (a quick-stop ramp keeps it on until each axis rests)
POWERED = np.array([int(State.OPERATION_ENABLED), int(State.QUICK_STOP_ACTIVE)], dtype=np.uint8)

# The tick's glue arithmetic, one definition each: Tick's reference stages call these, the
# fused call (hofto_hw/runtime/fused.py) their compiled form (``jit`` of the same function).


def command_dt(dt: float, period: float) -> float:
    """The setpoint (path) time step of a tick ``dt`` [s] after the last one: at most one
    ``period`` [s] (0: unknown): an interpolator that missed cycles is late, it does not jump."""
    return dt if period <= 0.0 or dt <= period else period


def jump_gap(since_fresh: float, period: float) -> float:
    """The time [s] beyond one ``period`` since the last fresh sample (``since_fresh`` [s],
    this tick's dt included): the position-jump check's allowance for lost cycles (0 within
    one period, or when the period is unknown)."""
    gap = since_fresh - period if period > 0.0 else 0.0
    return gap if gap > 1e-9 else 0.0


#: observer steps over one stalled gap at most (cost: one step each)
MAX_SUBSTEPS = 250


def gap_steps(dt: float, period: float) -> int:
    """Observer steps for a tick ``dt`` [s] after the last one: 1, or after a stall (more than
    1.5 periods) one per period, at most MAX_SUBSTEPS (flight-log replay uses the same)."""
    if period > 0.0 and dt > 1.5 * period:
        return min(MAX_SUBSTEPS, round(dt / period))
    return 1


def lerp(prev: np.ndarray, now: np.ndarray, a: float, out: np.ndarray) -> None:
    """``out = prev + a·(now - prev)`` (n,): a stall's sub-step sample (flight-log replay
    interpolates with the same operations, so its estimates are the loop's bit for bit)."""
    for j in range(out.shape[0]):
        out[j] = (now[j] - prev[j]) * a + prev[j]


def judged(tick: int, judge_from: int, flags: int) -> bool:
    """The collision monitor judges this ``tick`` (its data otherwise trusted): it has settled
    since the last (re)start (``judge_from``) and the power stage is on (``flags`` of
    :func:`tick_flags`: with it off the brakes act and the motor torque no longer explains
    the motion)."""
    return tick >= judge_from and flags & POWER_ON != 0


@jit
def tick_flags(
    tau_ext: np.ndarray, states: np.ndarray, powered: np.ndarray, qdd: np.ndarray, out: np.ndarray
) -> int:
    """Flags of this tick: ESTIMATES_FINITE when every element of ``tau_ext`` (k, n) is finite,
    POWER_ON when some entry of ``states`` (n,) is one of ``powered`` (the power stage is on);
    and ``out[:] = qdd`` (n,) (the monitor's reference acceleration into the tick record)."""
    flags = ESTIMATES_FINITE
    for i in range(tau_ext.shape[0]):
        for j in range(tau_ext.shape[1]):
            if not math.isfinite(tau_ext[i, j]):
                flags = 0
    for j in range(states.shape[0]):
        for p in range(powered.shape[0]):
            if states[j] == powered[p]:
                flags |= POWER_ON
    for j in range(qdd.shape[0]):
        out[j] = qdd[j]
    return flags
