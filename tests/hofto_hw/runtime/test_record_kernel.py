"""The compiled fill of the tick record (hofto_hw.recording.kernels.fill_tick) writes the same
bytes as a field-by-field numpy reference (kept here), and so does the same function run as
Python: tick by tick in the running loop and on odd values (non-finite samples, large fault
masks, negative bus status)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from support.compiled import require_compiled_kernels

from hofto_hw.config.models import SystemConfig
from hofto_hw.control.joint_motion import MOVE
from hofto_hw.recording.kernels import fill_tick
from hofto_hw.runtime import compose
from hofto_hw.runtime.compose import build
from hofto_hw.runtime.fused import section57

require_compiled_kernels()


def _fill_reference(tick: Any, status: int, wakeup_us: float, compute_us: float) -> None:
    """The reference fill of the tick record (field by field, numpy)."""
    r = tick.tick_rec
    r["t"] = tick.t
    r["tick"] = tick.tick
    r["q"] = tick.group.q
    r["qd"] = tick.group.qd
    r["tau"] = tick.group.tau
    r["q_cmd"] = tick.motion.q
    r["tau_ext"] = tick.tau_ext
    r["mode"] = tick.motion.mode
    r["faults"] = tick.stop.latched
    r["bus_status"] = status
    r["wakeup_us"] = wakeup_us
    r["compute_us"] = compute_us
    r["sample_dt"] = tick.st["sample_dt"]
    np.copyto(tick.q_sent, tick.motion.q)


def _refill(tick: Any, fill: Any, status: int, wakeup: float, compute: float) -> bytes:
    """Clear the record but for the fields other stages write, fill it with ``fill``."""
    rec = tick.tick_rec
    filled = rec.tobytes()
    rec[...] = np.zeros((), dtype=rec.dtype)  # the fill must write every field
    for field in ("wrench", "monitored", "qdd_cmd"):
        rec[field] = np.frombuffer(filled, dtype=rec.dtype)[field][0]
    fill(tick, status, wakeup, compute)
    return rec.tobytes()


def _python(tick: Any, status: int, wakeup: float, compute: float) -> None:
    m = tick.motion
    fill_tick.py_func(
        tick._rec1, tick.group.sample, m.q, tick.tau_ext, tick.q_sent, float(tick.t), tick.tick,
        m.mode, tick.stop.latched, int(status), float(wakeup), float(compute),
        float(tick.st["sample_dt"]),
    )  # fmt: skip


def test_kernel_fill_equals_the_reference_fill(
    cfg: SystemConfig, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(compose, "observer_backend", lambda: "auto")
    system = build(cfg, clock="sim", contact=False)
    tick = system.tick
    assert tick.backend == "numba"
    tick.mode_request = MOVE
    rng = np.random.default_rng(2)
    rec = tick.tick_rec
    t = 0.0
    for k in range(400):
        t += 1e-3
        wakeup, compute = float(rng.uniform(0, 500)), float(rng.uniform(0, 500))
        tick.step(t, 1e-3, wakeup, 0, compute)
        filled = rec.tobytes()
        assert _refill(tick, _fill_reference, tick.group.status, wakeup, compute) == filled, k
        if k % 50 == 0:
            assert _refill(tick, _python, tick.group.status, wakeup, compute) == filled, k
    # odd values, written by every fill into the same record
    g = tick.group
    g.q[2] = np.nan
    g.qd[0] = -np.inf
    tick.tau_ext[-1, 5] = np.inf
    tick.t, tick.tick = 1e9, 2**40
    tick.stop.latched = 2**31 + 5
    m = tick.motion
    section57(  # the record fill as the tick calls it (what = 0: no path, no feed-forward)
        tick._fz_args[0], tick._fz_args[3], tick._rec1, tick.t, tick.tick, 0, m.mode,
        tick.stop.latched, -3, 1e-40, 3e38,
    )  # fmt: skip
    filled = rec.tobytes()
    assert _refill(tick, _fill_reference, -3, 1e-40, 3e38) == filled
    assert _refill(tick, _python, -3, 1e-40, 3e38) == filled
