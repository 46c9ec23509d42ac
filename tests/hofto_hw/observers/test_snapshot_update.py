"""One shared snapshot per tick gives every observer exactly what its own update gives."""

from __future__ import annotations

import numpy as np
import pytest

from hofto_hw import jit
from hofto_hw.model.snapshot import DynamicsSnapshot, Needs
from hofto_hw.observers import OBSERVER_TYPES, make_observer
from hofto_hw.observers.registry import replay_default


def _inputs(model, steps=400, seed=9):
    rng = np.random.default_rng(seed)
    t = np.arange(steps) * 1e-3
    q = model.home + 0.3 * np.sin(np.outer(t, rng.uniform(0.5, 4, 6)))
    qd = np.gradient(q, 1e-3, axis=0) + rng.normal(0, 1e-3, (steps, 6))
    tau = rng.normal(0, 5.0, (steps, 6)) + np.array([0, 12, 5, 0, 0.1, 0])
    qd[150, 2] = np.nan  # one non-finite sample on the way
    return q, qd, tau


@pytest.mark.parametrize("backend", ["python", "auto"])
def test_update_snapshot_equals_update_for_every_observer(er3a_model, backend):
    q, qd, tau = _inputs(er3a_model)

    def build():
        return {
            name: make_observer(replay_default(name, 6), er3a_model, backend=backend)
            for name in OBSERVER_TYPES
        }

    alone, shared = build(), build()
    needs = Needs.NONE
    for obs in shared.values():
        needs |= obs.needs
    snap = DynamicsSnapshot(er3a_model, needs, backend)  # the terms as the observers' own
    for obs in (*alone.values(), *shared.values()):
        obs.reset(q[0], qd[0])
    for k in range(len(q)):
        snap.compute(q[k], qd[k], tau[k])
        for name in OBSERVER_TYPES:
            a = alone[name].update(q[k], qd[k], tau[k], 1e-3)
            b = shared[name].update_snapshot(snap, 1e-3)
            np.testing.assert_array_equal(a, b, err_msg=f"{name} at sample {k}")
            assert np.all(np.isnan(b)) == (k == 150), f"{name} at sample {k}"


def test_backend_auto_falls_back_to_numpy_when_compiled_kernels_are_off(er3a_model, monkeypatch):
    monkeypatch.setattr(jit, "_DISABLED", True)
    assert not jit.available()
    assert "HOFTO_HW_NO_NUMBA" in jit.unavailable_reason()
    obs = make_observer(replay_default("hofto", 6), er3a_model, backend="auto")
    assert obs.backend == "python"
    with pytest.raises(RuntimeError, match="unavailable"):
        make_observer(replay_default("momentum", 6), er3a_model, backend="numba")


def test_a_failing_compilation_marks_the_compiled_path_unavailable(monkeypatch):
    monkeypatch.setattr(jit, "_FAILED", "")
    monkeypatch.setattr(jit, "_DISABLED", False)

    def broken() -> None:
        raise TypeError("no matching definition\nsecond line")

    assert jit.warm(broken) is False
    assert not jit.available()
    assert jit.unavailable_reason() == (
        "compiling the kernels failed (TypeError: no matching definition"
    )
    assert jit.resolve("auto") == "python"
