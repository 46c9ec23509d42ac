"""A NaN or inf sample must not leave an observer producing NaN after reset (issue 7, defect 1)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from hofto_hw.observers import make_observer

NAMES = ["hofto", "eso", "dob", "momentum", "sta", "direct"]
DT = 1e-3


@pytest.mark.parametrize("bad", [np.nan, np.inf])
@pytest.mark.parametrize("where", ["q", "qd", "tau"])
@pytest.mark.parametrize("name", NAMES)
def test_reset_recovers_from_a_nonfinite_sample(er3a_config, er3a_model, name, where, bad):
    model = er3a_model
    obs = make_observer(er3a_config.observers[name], model)
    q = model.home.copy()
    qd = np.zeros(model.n)
    tau = np.zeros(model.n)
    tau[:] = pin.computeGeneralizedGravity(model.pin_model, pin.Data(model.pin_model), q)
    obs.reset(q, qd)
    for _ in range(5):
        obs.update(q, qd, tau, DT)
    sample = {"q": q.copy(), "qd": qd.copy(), "tau": tau.copy()}
    sample[where][2] = bad
    obs.update(sample["q"], sample["qd"], sample["tau"], DT)
    obs.reset(q, qd)
    for _ in range(20):
        est = obs.update(q, qd, tau, DT)
    assert np.all(np.isfinite(est)), f"{name} after a {bad} in {where} and reset: {est}"
    assert np.allclose(est, 0.0, atol=1.0), f"{name}: {est}"


@pytest.mark.parametrize("where", ["q", "qd", "tau"])
@pytest.mark.parametrize("name", NAMES)
def test_nonfinite_sample_is_reported_not_ingested(er3a_config, er3a_model, name, where):
    """The tick with a NaN input gives NaN (the fault stays visible downstream); the state is
    not poisoned, so the next finite samples give finite estimates without a reset."""
    model = er3a_model
    obs = make_observer(er3a_config.observers[name], model)
    q = model.home.copy()
    qd = np.zeros(model.n)
    tau = pin.computeGeneralizedGravity(model.pin_model, pin.Data(model.pin_model), q)
    obs.reset(q, qd)
    for _ in range(5):
        obs.update(q, qd, tau, DT)
    sample = {"q": q.copy(), "qd": qd.copy(), "tau": tau.copy()}
    sample[where][1] = np.nan
    bad = obs.update(sample["q"], sample["qd"], sample["tau"], DT)
    assert np.all(np.isnan(bad))
    for _ in range(20):
        est = obs.update(q, qd, tau, DT)
    assert np.all(np.isfinite(est)), f"{name} after a NaN in {where}: {est}"
    assert np.allclose(est, 0.0, atol=1.0), f"{name}: {est}"
