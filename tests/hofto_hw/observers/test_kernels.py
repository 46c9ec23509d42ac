"""The observers (their kernels, compiled and run as Python) against the numpy reference
(tests/hofto_hw/observers/reference.py): 1e-12 over thousands of random steps, non-finite
samples and Remark 7's equivalences included.

The compiled path must run here (tests/support/compiled.py: a failure under CI, else a skip).
"""

from __future__ import annotations

from math import comb

import numpy as np
import pytest
from support.compiled import require_compiled_kernels

from hofto_hw.observers import (
    DobObserver,
    EsoObserver,
    HoftoObserver,
    MomentumObserver,
    StaObserver,
)
from hofto_hw.observers.registry import levant_gains

from . import reference

require_compiled_kernels()

STEPS = 3000
TOL = 1e-12


def _inputs(model, steps=STEPS, seed=11, nan_at=()):
    rng = np.random.default_rng(seed)
    t = np.arange(steps) * 1e-3
    q = (
        model.home
        + 0.3 * np.sin(np.outer(t, rng.uniform(0.5, 4, 6)))
        + rng.normal(0, 1e-4, (steps, 6))
    )
    qd = np.gradient(q, 1e-3, axis=0) + rng.normal(0, 1e-3, (steps, 6))
    tau = rng.normal(0, 5.0, (steps, 6)) + np.array([0, 12, 5, 0, 0.1, 0])
    for k, what, j in nan_at:
        {"q": q, "qd": qd, "tau": tau}[what][k, j] = np.nan
    return q, qd, tau


def _run(obs, q, qd, tau, dt=1e-3):
    obs.reset(q[0], qd[0])
    return np.array([obs.update(q[k], qd[k], tau[k], dt).copy() for k in range(len(q))])


def _agree(make, model, python_steps=300, **kw):
    """The observer ``make(backend)`` builds, compiled (every sample) and run as Python (the
    first ``python_steps``: the same source, ~10-100x slower), against ``make("reference")``."""
    q, qd, tau = _inputs(model, **kw)
    ref = make("reference")
    fast = make("numba")
    slow = make("python")
    assert (fast.backend, slow.backend) == ("numba", "python")
    a = _run(ref, q, qd, tau)
    b = _run(fast, q, qd, tau)
    c = _run(slow, q[:python_steps], qd[:python_steps], tau[:python_steps])
    finite = np.isfinite(a)
    np.testing.assert_array_equal(finite, np.isfinite(b))
    assert np.abs(a[finite]).max() > 1.0  # the inputs excite the observer
    scale = np.abs(a[finite]).max()
    np.testing.assert_allclose(b[finite], a[finite], rtol=TOL, atol=TOL * scale)
    # the interpreted kernel is the compiled one's source: the same numbers, but for the
    # rounding of libm against Python's math (to the same tolerance)
    np.testing.assert_array_equal(np.isfinite(c), np.isfinite(b[:python_steps]))
    ok = np.isfinite(c)
    np.testing.assert_allclose(c[ok], b[:python_steps][ok], rtol=TOL, atol=TOL * scale)
    return a, b


def _build(cls, *args):
    """``make(backend)`` for the observer class ``cls``: its reference for "reference"."""

    def make(backend):
        if backend == "reference":
            return reference.REFERENCE[cls.__name__](*args)
        return cls(*args, backend=backend)

    return make


HOFTO_CASES = [
    # (order, form, discretisation, substeps, powers)
    (2, "recursive", "taylor", 1, [0.75, 2 / 3, 0.5, 0.0]),
    (1, "recursive", "taylor", 1, [2 / 3, 0.5, 0.0]),
    (3, "recursive", "taylor", 2, [0.8, 0.75, 2 / 3, 0.5, 0.0]),
    (2, "eq17", "euler", 3, [0.9, 0.8, 0.7, 0.6]),
    (2, "eq17", "taylor", 1, [0.75, 2 / 3, 0.5, 0.0]),
    (2, "recursive", "euler", 1, [1.0, 1.0, 1.0, 1.0]),
    # the main job's form (configs/er3a.yaml loop.observers): eq. (17)'s powers 1 + i·sigma
    (2, "eq17", "taylor", 4, [0.95, 0.9, 0.85, 0.8]),
    # roots the kernel takes without a logarithm, in both forms
    (2, "recursive", "taylor", 1, [0.75, 0.5, 0.25, 0.0]),
    (2, "eq17", "taylor", 2, [0.75, 0.5, 0.25, 0.0]),
]


@pytest.mark.parametrize(("order", "form", "disc", "substeps", "powers"), HOFTO_CASES)
def test_hofto_kernel_matches_the_reference(er3a_model, order, form, disc, substeps, powers):
    k = order + 2
    if form == "recursive":  # Levant's gains, L = 1000 rad/s^4
        gains = np.array(levant_gains(1000.0, 6, (12.0, 8.0, 5.0, 3.0, 1.5, 1.1)[-k:]))
    else:  # all poles of the linear part at -20 rad/s: binomial(k, i)·20^i
        w0 = 20.0
        gains = np.outer([comb(k, i) * w0**i for i in range(1, k + 1)], np.ones(6))

    make = _build(HoftoObserver, er3a_model, gains, np.array(powers), form, substeps, disc)
    _agree(make, er3a_model)


def test_eso_kernel_matches_the_reference(er3a_model):
    for substeps in (1, 3):
        k = (np.full(6, 45.0), np.full(6, 675.0), np.full(6, 3375.0))
        _agree(_build(EsoObserver, er3a_model, *k, substeps), er3a_model)


def test_sta_kernel_matches_the_reference(er3a_model):
    for substeps in (1, 2):
        gains = (np.full(6, 20.0), np.full(6, 100.0), np.full(6, 300.0))
        _agree(_build(StaObserver, er3a_model, *gains, substeps), er3a_model)


def test_momentum_kernel_matches_the_reference(er3a_model):
    _agree(_build(MomentumObserver, er3a_model, np.full(6, 50.0)), er3a_model)


def test_dob_kernel_matches_the_reference(er3a_model):
    _agree(_build(DobObserver, er3a_model, np.full(6, 30.0)), er3a_model)


def test_nonfinite_samples_give_nan_and_keep_state_on_every_path(er3a_model):
    nan_at = [(500, "q", 1), (501, "qd", 3), (1200, "tau", 0), (1201, "tau", 5)]
    makers = [
        _build(
            HoftoObserver,
            er3a_model,
            np.outer([50.0, 80.0, 60.0, 40.0], np.ones(6)),
            np.array([0.75, 2 / 3, 0.5, 0.0]),
        ),
        _build(EsoObserver, er3a_model, np.full(6, 45.0), np.full(6, 675.0), np.full(6, 3375.0)),
        _build(StaObserver, er3a_model, np.full(6, 20.0), np.full(6, 100.0), np.full(6, 300.0)),
        _build(MomentumObserver, er3a_model, np.full(6, 50.0)),
        _build(DobObserver, er3a_model, np.full(6, 30.0)),
    ]
    for make in makers:  # the interpreted kernel through the first NaN and beyond
        a, b = _agree(make, er3a_model, python_steps=520, nan_at=nan_at)
        for k, _, _ in nan_at:
            assert np.all(np.isnan(a[k])) and np.all(np.isnan(b[k]))
        assert np.all(np.isfinite(b[1202:]))


def test_remark7_equivalences_hold_on_the_compiled_path(er3a_model):
    q, qd, tau = _inputs(er3a_model, seed=5)
    k1, k2, k3 = np.full(6, 8.0), np.full(6, 50.0), np.full(6, 300.0)
    for substeps in (1, 3):
        eso = _run(EsoObserver(er3a_model, k1, k2, k3, substeps, "numba"), q, qd, tau)
        hofto = _run(
            HoftoObserver(
                er3a_model,
                np.vstack([k1, k2, k3]),
                np.ones(3),
                "eq17",
                substeps,
                "euler",
                backend="numba",
            ),
            q,
            qd,
            tau,
        )
        assert np.abs(eso).max() > 1.0
        np.testing.assert_allclose(hofto, eso, rtol=1e-9, atol=1e-9)
    l1, l2, l3 = np.full(6, 20.0), np.full(6, 100.0), np.full(6, 300.0)
    sta = _run(StaObserver(er3a_model, l1, l2, l3, 1, "numba"), q, qd, tau)
    hofto = _run(
        HoftoObserver(
            er3a_model,
            np.vstack([l1, l2, l3]),
            np.array([0.5, 0.5, 0.0]),
            "eq17",
            1,
            "euler",
            backend="numba",
        ),
        q,
        qd,
        tau,
    )
    assert np.abs(sta).max() > 1.0
    np.testing.assert_allclose(hofto, sta, rtol=1e-9, atol=1e-9)
