"""The observer bank gives every observer's estimate exactly as its own update_snapshot does,
writes it into the caller's rows, and falls back to the per-observer calls without numba."""

from __future__ import annotations

import numpy as np
import pytest

from hofto_hw import jit
from hofto_hw.model.snapshot import DynamicsSnapshot, Needs
from hofto_hw.observers.bank import _TERMS, ObserverBank
from hofto_hw.observers.direct import DirectObserver
from hofto_hw.observers.dob import DobObserver
from hofto_hw.observers.eso import EsoObserver, bandwidth_gains
from hofto_hw.observers.hofto import HoftoObserver
from hofto_hw.observers.momentum import MomentumObserver
from hofto_hw.observers.registry import levant_gains
from hofto_hw.observers.sta import StaObserver

from .reference import sigma_powers

needs_numba = pytest.mark.skipif(not jit.available(), reason=jit.unavailable_reason())


def _hofto(model, backend, order=2, form="recursive", substeps=1, disc="taylor"):
    n = model.n
    if form == "recursive":
        lam = (1.1, 1.5, 2.0, 3.0, 5.0, 8.0, 12.0, 18.0, 25.0, 32.0)[: order + 2][::-1]
        gains = np.array(levant_gains(80.0, n, lam))
    else:
        gains = np.array([[30.0 * (k + 1)] * n for k in range(order + 2)])
    powers = sigma_powers(order, -0.5 / (order + 3))
    return HoftoObserver(model, gains, powers, form, substeps, disc, backend=backend)


def _observers(model, backend):
    """Every fusable kind (HOFTO of three orders, forms, discretisations and substeps,
    momentum, ESO, STA, DOB) and one that is not (direct)."""
    n = model.n
    k1, k2, k3 = bandwidth_gains(np.full(n, 60.0))
    return [
        _hofto(model, backend),
        MomentumObserver(model, np.full(n, 40.0), backend=backend),
        _hofto(model, backend, order=1, form="eq17", disc="euler"),
        DirectObserver(model, accel_filter_hz=20.0),
        _hofto(model, backend, order=3, substeps=3),
        EsoObserver(model, k1, k2, k3, substeps=2, backend=backend),
        StaObserver(model, np.full(n, 20.0), np.full(n, 60.0), np.full(n, 20.0), 2, backend),
        DobObserver(model, np.full(n, 25.0), backend=backend),
    ]


def _snapshot(model, observers, backend):
    needs = Needs.NONE
    for obs in observers:
        needs |= obs.needs
    return DynamicsSnapshot(model, needs, backend)


def _agree(model, backend, steps=3000, seed=4):
    """Per-observer path vs the bank over ``steps`` random samples, with NaN and inf
    samples, non-finite dt, dt changes (stall sub-steps among them) and a reset."""
    rng = np.random.default_rng(seed)
    alone = _observers(model, backend)
    banked = _observers(model, backend)
    snap = _snapshot(model, banked, backend)
    out = np.full((len(banked), model.n), 7.0)
    bank = ObserverBank(banked, snap, out)
    q, qd = model.home.copy(), np.zeros(model.n)
    for obs in (*alone, *banked):
        obs.reset(q, qd)
    dts = (1e-3, 1e-3, 1e-3, 5e-4, 2e-3, 1e-3 / 3, 0.25e-3)
    nan_rows = 0
    for k in range(steps):
        if k == steps // 2:  # a reset mid-run, from the arm where it is
            snap.reset_memory()
            for obs in (*alone, *banked):
                obs.reset(q, qd)
        qd = 0.98 * qd + rng.normal(0.0, 0.05, model.n)
        q = q + 1e-3 * qd
        tau = rng.normal(0.0, 8.0, model.n) + np.array([0, 40, 15, 0, 1, 0])
        dt = dts[rng.integers(len(dts))]
        x = [q.copy(), qd.copy(), tau]
        u = rng.random()
        if u < 0.02:
            x[rng.integers(3)][rng.integers(model.n)] = np.nan
        elif u < 0.03:
            x[rng.integers(3)][rng.integers(model.n)] = -np.inf
        elif u < 0.035:
            dt = np.nan
        snap.compute(x[0], x[1], x[2])
        want = [obs.update_snapshot(snap, dt).copy() for obs in alone]
        bank.update(dt)
        for i, w in enumerate(want):
            np.testing.assert_array_equal(out[i], w, err_msg=f"{banked[i].name} row {i} step {k}")
        nan_rows += int(np.isnan(out).all())
    assert nan_rows > steps // 50  # the non-finite samples did occur (NaN in every row)
    assert np.isfinite(out).all()  # and the last sample is finite again
    return bank, alone, banked


@needs_numba
def test_bank_gives_the_per_observer_estimates_bit_for_bit(er3a_model):
    bank, alone, banked = _agree(er3a_model, "numba")
    assert bank.fused == ("hofto", "momentum", "hofto", "hofto", "eso", "sta", "dob")
    assert bank.rest == ("direct",)
    # the observers' own state is what the bank advanced: standalone use continues from it
    q, qd, tau = er3a_model.home, np.full(er3a_model.n, 0.1), np.full(er3a_model.n, 3.0)
    for a, b in zip(alone, banked, strict=True):
        np.testing.assert_array_equal(a.update(q, qd, tau, 1e-3), b.update(q, qd, tau, 1e-3))


def test_without_compiled_kernels_the_bank_calls_each_observer(er3a_model, monkeypatch):
    monkeypatch.setattr(jit, "_DISABLED", True)  # as HOFTO_HW_NO_NUMBA=1
    bank, _, banked = _agree(er3a_model, "auto", steps=600)
    assert all(obs.backend == "python" for obs in banked if hasattr(obs, "backend"))
    assert bank.fused == ()
    assert bank.rest == tuple(obs.name for obs in banked)


@needs_numba
def test_numpy_observers_beside_compiled_ones_run_through_their_own_update(er3a_model):
    n = er3a_model.n
    obs = [
        _hofto(er3a_model, "numba"),
        MomentumObserver(er3a_model, np.full(n, 40.0), backend="python"),
    ]
    snap = _snapshot(er3a_model, obs, "numba")
    bank = ObserverBank(obs, snap, np.zeros((2, n)))
    assert (bank.fused, bank.rest) == (("hofto",), ("momentum",))


@needs_numba
def test_the_bank_writes_only_its_rows_and_follows_the_owners_arrays(er3a_model):
    """Estimates land in the caller's array itself; a reset (in place) is seen by the bank;
    the snapshot keeps its term arrays across computes (the bank addresses them)."""
    n = er3a_model.n
    obs = [_hofto(er3a_model, "numba"), MomentumObserver(er3a_model, np.full(n, 40.0), "numba")]
    snap = _snapshot(er3a_model, obs, "numba")
    out = np.full((3, n), 5.0)  # one spare row the bank must not touch
    terms = [getattr(snap, a) for a in _TERMS]
    bank = ObserverBank(obs, snap, out)
    q, qd = er3a_model.home, np.zeros(n)
    for o in obs:
        o.reset(q, qd)
    tau = np.array([0.0, 60.0, 20.0, 0.0, 1.0, 0.0])
    for _ in range(50):
        snap.compute(q, qd, tau)
        bank.update(1e-3)
    assert np.abs(out[:2]).max() > 1.0  # unbalanced gravity torque read as external
    np.testing.assert_array_equal(out[2], 5.0)
    assert all(t is getattr(snap, a) for t, a in zip(terms, _TERMS, strict=True))
    assert bank.bound()
    for o in obs:
        o.reset(q, qd)
    snap.compute(q, qd, snap.g.copy() + snap.f)  # the static torque: nothing external
    bank.update(1e-3)
    assert np.abs(out[:2]).max() < 1e-6
    obs[1].r = np.zeros(n)  # an owner that rebinds an array: the bank says so
    assert not bank.bound()


def test_bad_output_arrays_are_refused(er3a_model):
    obs = [MomentumObserver(er3a_model, np.full(er3a_model.n, 40.0))]
    snap = _snapshot(er3a_model, obs, "python")
    with pytest.raises(ValueError, match="rows"):
        ObserverBank(obs * 2, snap, np.zeros((1, er3a_model.n)))
    with pytest.raises(ValueError, match="C-contiguous"):
        ObserverBank(obs, snap, np.zeros((er3a_model.n, 2)).T)
