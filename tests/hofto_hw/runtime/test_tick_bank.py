"""The tick's observers through one ObserverBank give the per-observer estimates bit for bit,
stall sub-steps included."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hofto_hw import jit
from hofto_hw.config.loader import load_config
from hofto_hw.control.joint_motion import MOVE
from hofto_hw.observers.bank import ObserverBank
from hofto_hw.runtime.compose import build
from tests.support.reference_tick import use_reference

CONFIG = Path(__file__).resolve().parents[3] / "configs" / "er3a.yaml"


@pytest.mark.skipif(not jit.available(), reason=jit.unavailable_reason())
def test_the_banked_tick_equals_the_per_observer_tick_over_stalls() -> None:
    cfg = load_config(CONFIG)
    fused, alone = build(cfg, clock="sim", contact=False), build(cfg, clock="sim", contact=False)
    try:
        use_reference(alone)  # the stages on every tick: the bank's own update
        t = alone.tick
        t._bank = ObserverBank(t.observers, t.snapshot, t.tau_ext, fuse=False)
        assert fused.tick._bank.fused == ("hofto", "momentum") and t._bank.fused == ()
        period = 1.0 / fused.rate_hz
        stalls = 0
        now = 0.0
        for s in (fused, alone):
            s.tick.mode_request = MOVE
        for k in range(1, 1201):
            # a real clock's jitter, and stalls of 2-5 cycles
            dt = period * (1 + k % 5) if k % 97 == 0 else period * (1.0 + 0.02 * np.sin(k))
            stalls += dt > period
            now += dt
            for s in (fused, alone):
                s.tick.step(now, dt, 0.0, 0, 0.0)
            np.testing.assert_array_equal(fused.tick.tau_ext, t.tau_ext, err_msg=f"tick {k}")
        assert stalls >= 10
        assert np.abs(t.tau_ext).max() > 0.0 and np.isfinite(t.tau_ext).all()
    finally:
        fused.close()
        alone.close()


@pytest.mark.skipif(not jit.available(), reason=jit.unavailable_reason())
def test_an_observer_that_rebinds_its_state_on_reset_gets_a_new_bank() -> None:
    """The bank passes its owners' records: when a reset hands an observer new arrays, the
    tick builds a new bank instead of integrating the dropped ones; the compiled call cannot
    run an observer outside its record, so the tick refuses to go on (one error naming it),
    and the reference integrates the new array."""
    cfg = load_config(CONFIG)
    system = build(cfg, clock="sim", contact=False)
    try:
        tick = system.tick
        momentum = tick.observers[tick.names.index("momentum")]
        plain_reset = momentum.reset

        def rebinding_reset(q: np.ndarray, qd: np.ndarray) -> None:
            momentum.r = np.zeros_like(momentum.r)  # a new array, not the bank's
            plain_reset(q, qd)

        momentum.reset = rebinding_reset
        period = 1.0 / system.rate_hz
        tick.mode_request = MOVE
        for k in range(1, 301):
            tick.step(k * period, period, 0.0, 0, 0.0)
        old_bank = tick._bank
        # resets every observer: momentum rebinds r. Its state no longer in its record, the
        # compiled call cannot run it: refused, naming it (no silent Python path)
        with pytest.raises(RuntimeError, match="not fused in the bank: momentum"):
            tick.start()
        assert tick._bank is not old_bank and tick._bank.bound()
        assert tick._bank.fused == ("hofto",) and tick._bank.rest == ("momentum",)
        use_reference(system)  # the reference: the observer through its own update
        for k in range(301, 401):
            tick.step(k * period, period, 0.0, 0, 0.0)
        row = tick.tau_ext[tick.names.index("momentum")]
        np.testing.assert_array_equal(row, momentum.r)  # the bank integrates the new array
    finally:
        system.close()
