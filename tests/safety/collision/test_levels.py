"""Two-level collision detection: contact self-clears, collision reports a latched stop,
phase thresholds, observer choice with any/all, per-row first crossing."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
from pydantic import ValidationError

from hofto_hw.config.safety import CollisionLevelsConfig, StopCategories
from safety.collision import CollisionLevels
from safety.stop import EventKind, Fault, StopController

DT = 1e-3


def _cfg(**kw) -> CollisionLevelsConfig:
    base = {
        "contact": {"nominal": [2.0, 2.0], "acceleration": [3.0, 3.0]},
        "collision": {"nominal": [5.0, 5.0], "acceleration": [8.0, 8.0]},
        "release_time": 0.01,
    }
    base.update(kw)
    return CollisionLevelsConfig.model_validate(base)


def _run(mon: CollisionLevels, stop: StopController, est, ticks=1, qdd=0.0) -> None:
    z = np.zeros(2)
    for _ in range(ticks):
        stop.begin_tick(stop.tick + 1)
        mon.update(stop, np.asarray(est, float), z, z, np.full(2, qdd), DT)


def test_contact_is_reported_and_clears_collision_latches() -> None:
    mon = CollisionLevels(_cfg(), ["hofto", "momentum"])
    stop = StopController.from_config(StopCategories())
    _run(mon, stop, [[3.0, 0.0], [0.0, 0.0]])
    assert mon.contact and not mon.collision and stop.latched == 0
    assert stop.events.kind[0] == EventKind.CONTACT
    _run(mon, stop, [[0.0, 0.0], [0.0, 0.0]], ticks=20)
    assert not mon.contact  # clears itself
    _run(mon, stop, [[6.0, 0.0], [0.0, 0.0]])
    assert mon.collision and stop.is_latched(Fault.COLLISION)
    assert mon.first_tick[0] == stop.first_tick and mon.first_tick[1] == -1
    _run(mon, stop, [[0.0, 0.0], [0.0, 0.0]], ticks=20)
    assert not mon.collision and stop.is_latched(Fault.COLLISION)  # the latch stays


def test_acceleration_phase_uses_its_own_thresholds() -> None:
    mon = CollisionLevels(_cfg(), ["hofto"])
    stop = StopController.from_config(StopCategories())
    _run(mon, stop, [[6.0, 0.0]], qdd=5.0)
    assert mon.accel_phase and not mon.collision
    _run(mon, stop, [[0.0, 0.0]], ticks=200)
    assert not mon.accel_phase  # phase_hold has passed
    _run(mon, stop, [[6.0, 0.0]])
    assert mon.collision


@pytest.mark.parametrize(("logic", "trips"), [("any", True), ("all", False)])
def test_both_observers_any_or_all(logic: str, trips: bool) -> None:
    mon = CollisionLevels(_cfg(observer="both", logic=logic), ["hofto", "momentum"])
    stop = StopController.from_config(StopCategories())
    _run(mon, stop, [[6.0, 0.0], [1.0, 0.0]])
    assert mon.collision is trips
    _run(mon, stop, [[6.0, 0.0], [6.0, 0.0]])
    assert mon.collision


def test_momentum_can_decide() -> None:
    mon = CollisionLevels(_cfg(observer="momentum"), ["hofto", "momentum"])
    stop = StopController.from_config(StopCategories())
    _run(mon, stop, [[9.0, 0.0], [0.0, 0.0]])
    assert not mon.collision and mon.first_tick[0] > 0  # hofto crossed, did not decide
    _run(mon, stop, [[0.0, 0.0], [0.0, 9.0]])
    assert mon.collision and stop.events.joint[stop.events.count - 1] == 1


def test_non_finite_estimate_does_not_poison() -> None:
    mon = CollisionLevels(_cfg(), ["hofto"])
    stop = StopController.from_config(StopCategories())
    _run(mon, stop, [[np.nan, np.nan]])
    assert not mon.collision  # NaN: the limit monitor reports it (NON_FINITE)
    _run(mon, stop, [[6.0, 0.0]])
    assert mon.collision  # no state was poisoned
    mon2 = CollisionLevels(_cfg(), ["hofto"])
    stop2 = StopController.from_config(StopCategories())
    _run(mon2, stop2, [[0.0, np.inf]])
    # one monitor with CollisionMonitor's rule (issue 11): an infinite estimate is the
    # NON_FINITE fault (category 0 by default, stronger than a collision stop), not a ratio
    assert stop2.is_latched(Fault.NON_FINITE) and mon2.nonfinite[1] and not mon2.collision


def test_config_checks() -> None:
    with pytest.raises(ValidationError, match="contact must be the lower level"):
        _cfg(contact={"nominal": [6.0, 2.0], "acceleration": [3.0, 3.0]})
    with pytest.raises(ValidationError, match="finite"):
        _cfg(acceleration_phase=float("inf"))
    with pytest.raises(ValueError, match="needs estimates from"):
        CollisionLevels(_cfg(observer="momentum"), ["hofto"])


def test_update_allocates_nothing() -> None:
    mon = CollisionLevels(_cfg(velocity_gain=[0.5, 0.5]), ["hofto", "momentum"])
    stop = StopController.from_config(StopCategories())
    est = np.array([[1.0, -1.0], [0.5, 0.2]])
    _run(mon, stop, est, ticks=10)
    tracemalloc.start()
    before = tracemalloc.get_traced_memory()[0]
    _run(mon, stop, est, ticks=2000)
    grown = tracemalloc.get_traced_memory()[1] - before
    tracemalloc.stop()
    assert grown < 2000
