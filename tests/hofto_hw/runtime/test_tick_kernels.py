"""The tick's compiled flags call (hofto_hw.runtime.tick_kernels.tick_flags) answers as a numpy
reference (kept here) does, and so does the same function run as Python: finiteness of the
estimates (NaN, ±inf in any row), the power stage (operation enabled or quick-stop active on
any axis) and the copy of qdd, bit for bit."""

from __future__ import annotations

import numpy as np
from support.compiled import require_compiled_kernels

from drivers.cia402.state_machine import State
from hofto_hw.runtime.tick_kernels import ESTIMATES_FINITE, POWER_ON, tick_flags
from hofto_hw.runtime.tick_kernels import POWERED as _POWERED

require_compiled_kernels()


def tick_flags_numpy(
    tau_ext: np.ndarray, states: np.ndarray, powered: np.ndarray, qdd: np.ndarray, out: np.ndarray
) -> int:
    """The reference of :func:`tick_flags` (the tick's code before the kernel). The finiteness
    is one sum: a sum that overflows to inf says 'not finite' where the kernel does not, and
    the tick then only runs its per-row checks, which report nothing (the same outcome)."""
    flags = ESTIMATES_FINITE if np.isfinite(np.add.reduce(tau_ext, axis=None)) else 0
    if np.isin(states, powered).any():
        flags |= POWER_ON
    np.copyto(out, qdd)
    return flags


_STATES = np.array([int(s) for s in State], dtype=np.uint8)


def test_flags_agree_with_numpy_reference() -> None:
    rng = np.random.default_rng(12)
    seen = set()
    for trial in range(4000):
        k, n = int(rng.integers(1, 4)), 6
        tau_ext = rng.normal(scale=50.0, size=(k, n))
        for _ in range(int(rng.integers(0, 3)) if rng.random() < 0.3 else 0):
            tau_ext[rng.integers(k), rng.integers(n)] = rng.choice([np.nan, np.inf, -np.inf])
        states = rng.choice(_STATES, size=n).astype(np.uint8)
        if rng.random() < 0.3:  # often no axis powered
            states[:] = rng.choice(_STATES[~np.isin(_STATES, _POWERED)], size=n)
        qdd = rng.normal(size=n)
        qdd[rng.integers(n)] = rng.choice([np.nan, -0.0, np.inf, 1e-310])
        out_c, out_r = np.full(n, 7.0), np.full(n, 7.0)
        a = tick_flags(tau_ext, states, _POWERED, qdd, out_c)
        with np.errstate(invalid="ignore"):  # inf + -inf in the reference's sum
            b = tick_flags_numpy(tau_ext, states, _POWERED, qdd, out_r)
        assert a == b, trial
        assert out_c.tobytes() == qdd.tobytes() == out_r.tobytes(), trial
        if trial % 20 == 0:  # the same source as Python
            assert tick_flags.py_func(tau_ext, states, _POWERED, qdd, out_r) == a, trial
        assert bool(a & ESTIMATES_FINITE) == bool(np.isfinite(tau_ext).all())
        assert bool(a & POWER_ON) == bool(np.isin(states, _POWERED).any())
        seen.add(a)
    assert seen == {0, ESTIMATES_FINITE, POWER_ON, ESTIMATES_FINITE | POWER_ON}


def test_record_field_view_is_written() -> None:
    """The tick passes the record's qdd_cmd field (an unaligned view) as ``out``."""
    from hofto_hw.recording.record import new_record, tick_dtype

    rec = new_record(tick_dtype(6, 2))
    view = rec["qdd_cmd"]
    qdd = np.arange(6.0) - 2.5
    flags = tick_flags(np.zeros((2, 6)), np.full(6, int(State.OPERATION_ENABLED), np.uint8),
                       _POWERED, qdd, view)  # fmt: skip
    assert flags == ESTIMATES_FINITE | POWER_ON
    assert (rec["qdd_cmd"] == qdd).all()
