"""Remark 7: HOFTO with powers 1 (n = 1) is the ESO; with powers (1/2, 1/2, 0) it is the STA."""

from __future__ import annotations

import numpy as np

from hofto_hw.observers import EsoObserver, HoftoObserver, StaObserver


def _random_inputs(model, steps=3000, seed=3):
    rng = np.random.default_rng(seed)
    t = np.arange(steps) * 1e-3
    q = (
        model.home
        + 0.2 * np.sin(np.outer(t, rng.uniform(0.5, 3, 6)))
        + rng.normal(0, 1e-4, (steps, 6))
    )
    qd = np.gradient(q, 1e-3, axis=0) + rng.normal(0, 1e-3, (steps, 6))
    tau = rng.normal(0, 5.0, (steps, 6)) + np.array([0, 12, 5, 0, 0.1, 0])
    return q, qd, tau


def _run(obs, q, qd, tau, dt=1e-3):
    obs.reset(q[0], qd[0])
    return np.array([obs.update(q[k], qd[k], tau[k], dt).copy() for k in range(len(q))])


def test_hofto_with_unit_powers_is_the_eso(er3a_model):
    q, qd, tau = _random_inputs(er3a_model)
    k1, k2, k3 = np.full(6, 8.0), np.full(6, 50.0), np.full(6, 300.0)
    for substeps in (1, 3):
        eso = _run(EsoObserver(er3a_model, k1, k2, k3, substeps), q, qd, tau)
        hofto = _run(
            HoftoObserver(
                er3a_model, np.vstack([k1, k2, k3]), np.ones(3), "eq17", substeps, "euler"
            ),
            q,
            qd,
            tau,
        )
        assert np.abs(eso).max() > 1.0  # the inputs excite it
        np.testing.assert_allclose(hofto, eso, rtol=1e-9, atol=1e-9)


def test_hofto_with_sta_powers_is_the_sta(er3a_model):
    q, qd, tau = _random_inputs(er3a_model, seed=4)
    l1, l2, l3 = np.full(6, 20.0), np.full(6, 100.0), np.full(6, 300.0)
    sta = _run(StaObserver(er3a_model, l1, l2, l3), q, qd, tau)
    hofto = _run(
        HoftoObserver(
            er3a_model, np.vstack([l1, l2, l3]), np.array([0.5, 0.5, 0.0]), "eq17", 1, "euler"
        ),
        q,
        qd,
        tau,
    )
    assert np.abs(sta).max() > 1.0
    np.testing.assert_allclose(hofto, sta, rtol=1e-9, atol=1e-9)


def test_a_different_power_breaks_the_equivalence(er3a_model):
    """The equivalence tests above can fail: change one power and they do."""
    q, qd, tau = _random_inputs(er3a_model, seed=5)
    k = np.full(6, 10.0)
    eso = _run(EsoObserver(er3a_model, k, 10 * k, 30 * k), q, qd, tau)
    hofto = _run(
        HoftoObserver(
            er3a_model, np.vstack([k, 10 * k, 30 * k]), np.array([1, 1, 0.9]), "eq17", 1, "euler"
        ),
        q,
        qd,
        tau,
    )
    assert np.abs(hofto - eso).max() > 1e-3
