"""The loop runs the one collision monitor (safety/collision/) on the compiled path when numba
is there (issue 12); tests/safety/collision/test_kernel.py checks both paths agree."""

from __future__ import annotations

from hofto_hw import jit
from hofto_hw.config.models import SystemConfig
from hofto_hw.runtime.compose import build
from safety.collision import CollisionLevels


def test_loop_builds_the_monitor_on_the_auto_backend(cfg: SystemConfig) -> None:
    system = build(cfg, clock="sim", contact=False)
    mon = system.tick.collision
    assert isinstance(mon, CollisionLevels)
    assert mon.backend == jit.resolve("auto")
    assert mon.rows == ["hofto", "momentum"] and mon.levels == ("contact", "collision")
