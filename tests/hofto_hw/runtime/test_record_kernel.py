"""The compiled fill of the tick record (hofto_hw.recording.kernels.fill_tick) writes the same
bytes as the numpy reference fill, tick by tick in the running loop and on odd values
(non-finite samples, large fault masks, negative bus status)."""

from __future__ import annotations

import numpy as np
import pytest
from support.compiled import require_compiled_kernels

from hofto_hw.config.models import SystemConfig
from hofto_hw.control.joint_motion import MOVE
from hofto_hw.runtime import compose
from hofto_hw.runtime.compose import build

require_compiled_kernels()


def test_kernel_fill_equals_numpy_fill(cfg: SystemConfig, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(compose, "observer_backend", lambda: "auto")
    system = build(cfg, clock="sim", contact=False)
    tick = system.tick
    assert tick.backend == "numba" and tick._fill_kernel
    tick.mode_request = MOVE
    rng = np.random.default_rng(2)
    rec = tick.tick_rec
    t = 0.0
    for k in range(400):
        t += 1e-3
        wakeup, compute = float(rng.uniform(0, 500)), float(rng.uniform(0, 500))
        tick.step(t, 1e-3, wakeup, 0, compute)
        filled = rec.tobytes()
        rec[...] = np.zeros((), dtype=rec.dtype)  # the numpy fill must write every field
        rec["wrench"] = np.frombuffer(filled, dtype=rec.dtype)["wrench"][0]
        rec["monitored"] = np.frombuffer(filled, dtype=rec.dtype)["monitored"][0]
        rec["qdd_cmd"] = np.frombuffer(filled, dtype=rec.dtype)["qdd_cmd"][0]
        tick._fill_numpy(tick.group.status, wakeup, compute)
        assert rec.tobytes() == filled, k
    # odd values, written by both fills into the same record
    g = tick.group
    g.q[2] = np.nan
    g.qd[0] = -np.inf
    tick.tau_ext[-1, 5] = np.inf
    tick.t, tick.tick = 1e9, 2**40
    tick.stop.latched = 2**31 + 5
    tick._fill_kernel = True
    tick._record(-3, 1e-40, 3e38)
    filled = rec.tobytes()
    tick._fill_numpy(-3, 1e-40, 3e38)
    assert rec.tobytes() == filled
