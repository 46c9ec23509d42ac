"""The tick's section 4 judges the following error on fresh samples only: a lost frame's
repeated sample is an old position against a newer command (its lag is not the drive's), the
next fresh sample's lag is, and latches with the configured category in that tick. Through the
compiled call (hofto_hw/runtime/fused.py) and the Python reference (reference_tick.py)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from hofto_hw import jit
from hofto_hw.config.models import SystemConfig
from hofto_hw.control.joint_motion import MOVE
from hofto_hw.runtime.compose import build
from safety.kernels import FOLLOWING_ERROR, PARAMS
from safety.stop import Fault
from tests.support.reference_tick import use_reference

pytestmark = pytest.mark.skipif(not jit.available(), reason=jit.unavailable_reason())

#: the bound while the frame is lost: below every lag of a moving arm (what is judged, not
#: how large the lag is, is under test)
TIGHT = 1e-9


def _moving(cfg: SystemConfig, reference: bool) -> Any:
    cats = cfg.safety.categories.model_copy(update={"following_error": 2})  # not the default
    safety = cfg.safety.model_copy(update={"categories": cats})
    system = build(cfg.model_copy(update={"safety": safety}), clock="sim", contact=False)
    if reference:
        use_reference(system)
    system.tick.mode_request = MOVE
    system.loop.run(max_ticks=600)
    assert system.tick.stop.latched == 0
    assert np.abs(system.group.qd).max() > 0.1  # moving: the command runs ahead of q
    return system


@pytest.mark.parametrize("reference", [False, True], ids=["compiled", "reference"])
def test_a_stale_sample_is_no_following_error_the_next_fresh_one_is(
    cfg: SystemConfig, reference: bool
) -> None:
    system = _moving(cfg, reference)
    try:
        t, g, stop = system.tick, system.group, system.tick.stop
        t.limits._w[PARAMS, FOLLOWING_ERROR] = TIGHT
        system.bus.drop_cycles(1)
        q_cmd = t.q_sent.copy()  # what this tick's check compares the sample with
        system.loop.run(max_ticks=1)
        assert not g.fresh and np.abs(q_cmd - g.q).max() > TIGHT  # a lag, on a stale sample
        assert not stop.is_latched(Fault.FOLLOWING_ERROR), stop.latched_names()
        assert stop.latched == 0
        q_cmd = t.q_sent.copy()
        system.loop.run(max_ticks=1)
        assert g.fresh
        assert stop.is_latched(Fault.FOLLOWING_ERROR), stop.latched_names()
        e = stop.events
        mine = [i for i in range(e.count) if e.kind[i] == Fault.FOLLOWING_ERROR]
        assert len(mine) == 1
        i = mine[0]
        j = int(e.joint[i])
        assert e.tick[i] == t.tick and e.category[i] == 2
        assert j == int(np.argmax(np.abs(q_cmd - g.q) > TIGHT))  # the first lagging joint
        assert e.value[i] == pytest.approx(abs(q_cmd[j] - g.q[j]), rel=1e-12)
    finally:
        system.close()
