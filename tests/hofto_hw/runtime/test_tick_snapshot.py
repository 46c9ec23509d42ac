"""The tick computes one dynamics snapshot per tick and hands it to every observer: the same
estimates as each observer updating through its own snapshot, and no allocation. The tick
runs its compiled path only (a numpy-path part is refused when it is built); the snapshot's
own ``compute`` is what the test reference (tests/support/reference_tick.py) calls."""

from __future__ import annotations

import numpy as np
import pytest
from support.alloc import tick_memory

from hofto_hw import jit
from hofto_hw.config.models import SystemConfig
from hofto_hw.control.joint_motion import MOVE
from hofto_hw.model.snapshot import DynamicsSnapshot, Needs
from hofto_hw.observers import make_observer
from hofto_hw.runtime import compose
from hofto_hw.runtime.compose import build, loop_observer_table, shared_snapshot
from tests.support.reference_tick import use_reference

pytestmark = pytest.mark.skipif(not jit.available(), reason=jit.unavailable_reason())
BACKENDS = ["auto"]


def _system(cfg: SystemConfig, backend: str, monkeypatch: pytest.MonkeyPatch):
    monkeypatch.setattr(compose, "observer_backend", lambda: backend)
    system = build(cfg, clock="sim", contact=False)
    system.tick.mode_request = MOVE  # the demo path: the arm moves, every term varies
    return system


@pytest.mark.parametrize("backend", BACKENDS)
def test_shared_snapshot_gives_each_observers_own_estimates(
    cfg: SystemConfig, backend: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    system = _system(cfg, backend, monkeypatch)
    tick, g = system.tick, system.group
    table = loop_observer_table(cfg)
    twins = [make_observer(table[name], system.model, backend=backend) for name in tick.names]
    for twin, obs in zip(twins, tick.observers, strict=True):
        assert twin.backend == obs.backend
        twin.reset(g.q, g.qd)  # the state the tick's start reset its observers on
    dt = system.loop.period
    worst = np.zeros(len(twins))
    scale = np.zeros(len(twins))

    def compare() -> bool:  # after every tick of the loop (its stop check)
        for i, twin in enumerate(twins):
            est = twin.update(g.q, g.qd, g.tau, dt)
            worst[i] = max(worst[i], float(np.max(np.abs(est - tick.tau_ext[i]))))
            scale[i] = max(scale[i], float(np.max(np.abs(est))))
        return False

    assert system.loop.run(max_ticks=3000, should_stop=compare) == 3000
    assert tick.stop.latched == 0
    assert np.all(scale > 0.1)  # the estimates are not trivially zero
    assert np.all(worst <= 1e-12), worst


def test_one_snapshot_per_tick_for_the_union_of_needs(
    cfg: SystemConfig, monkeypatch: pytest.MonkeyPatch
) -> None:
    system = _system(cfg, "auto", monkeypatch)
    use_reference(system)  # the snapshot's own compute (the tick as built: its kernel)
    tick = system.tick
    union = Needs.NONE
    for obs in tick.observers:
        union |= obs.needs
    assert tick.snapshot.needs & union == union
    calls = []
    compute = DynamicsSnapshot.compute

    def counted(self, q, qd, tau):
        calls.append(self)
        return compute(self, q, qd, tau)

    monkeypatch.setattr(DynamicsSnapshot, "compute", counted)
    system.loop.run(max_ticks=50)
    assert len(calls) == 50 and all(s is tick.snapshot for s in calls)
    assert tick.snapshot.q is system.group.q  # the sample of this tick, not a copy


def test_shared_snapshot_takes_the_observers_implementation(
    cfg: SystemConfig, monkeypatch: pytest.MonkeyPatch
) -> None:
    system = _system(cfg, "auto", monkeypatch)
    table = loop_observer_table(cfg)
    plain = [
        make_observer(table[name], system.model, backend="python") for name in system.tick.names
    ]
    assert shared_snapshot(system.model, plain).backend == "python"
    compiled = [
        make_observer(table[name], system.model, backend="numba") for name in system.tick.names
    ]
    assert shared_snapshot(system.model, compiled).backend == "numba"
    assert system.tick.snapshot.backend == "numba"
    mixed = [compiled[0], *plain[1:]]
    assert shared_snapshot(system.model, mixed).backend == "python"


def test_a_snapshot_missing_a_term_is_refused(
    cfg: SystemConfig, monkeypatch: pytest.MonkeyPatch
) -> None:
    system = _system(cfg, "auto", monkeypatch)
    tick = system.tick
    with pytest.raises(ValueError, match="lacks terms"):
        type(tick)(
            tick.group,
            tick.observers,
            DynamicsSnapshot(system.model, Needs.MASS),
            tick.stop,
            tick.limits,
            tick.bus,
            tick.collision,
            tick.motion,
            tick.feedforward,
            tick.sink,
        )


@pytest.mark.parametrize("backend", BACKENDS)
def test_tick_with_shared_snapshot_allocates_nothing(
    cfg: SystemConfig, backend: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    system = _system(cfg, backend, monkeypatch)
    system.loop.run(max_ticks=1500)
    grown, peak = tick_memory(system)
    assert system.tick.stop.latched == 0
    # nothing kept per tick (3000 x one (6,) array would be > 300 kB), no large temporaries
    assert grown < 4000
    assert peak < 16000


def test_tick_record_and_sink_share_one_dtype_object(
    cfg: SystemConfig, monkeypatch: pytest.MonkeyPatch
) -> None:
    """numpy copies between arrays of one dtype object byte-wise; between equal but distinct
    dtype objects it builds a field-by-field cast on every copy (tens of µs in the tick)."""
    system = _system(cfg, "auto", monkeypatch)
    assert system.sink.ticks.dtype is system.tick.tick_rec.dtype
    system.loop.run(max_ticks=5)
    kept = system.sink.last_ticks()
    assert kept.shape[0] == 5 and np.array_equal(kept[-1]["q"], system.group.q)
