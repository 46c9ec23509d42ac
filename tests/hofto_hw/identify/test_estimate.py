"""OLS / WLS on synthetic data with known parameters; bad data give clear errors."""

from __future__ import annotations

import numpy as np
import pytest

from hofto_hw.errors import UserError
from hofto_hw.identify.estimate import Accumulator, least_squares
from hofto_hw.identify.pipeline import nominal_theta

from .conftest import smooth_motion


def _data(model, reg, noise=(0.0,) * 6, seed=0, duration=20.0):
    _, q, qd, qdd = smooth_motion(model.n, duration, 100.0, seed)
    theta = nominal_theta(model)
    tau = (reg.stack(q, qd, qdd) @ theta).reshape(q.shape)
    rng = np.random.default_rng(seed + 100)
    tau += rng.normal(0.0, 1.0, tau.shape) * np.asarray(noise)
    return q, qd, qdd, tau, theta


def test_noise_free_recovery_and_chunking(er3a_model, er3a_base) -> None:
    reg, base = er3a_base
    q, qd, qdd, tau, theta = _data(er3a_model, reg)
    acc = Accumulator(reg, base, chunk=333)  # several chunks, uneven last one
    acc.add(q, qd, qdd, tau)
    est = least_squares(acc)
    mu = base.from_standard(theta)
    assert np.linalg.norm(est.mu - mu) / np.linalg.norm(mu) < 1e-9
    assert np.all(est.rmse < 1e-8)
    assert est.samples == q.shape[0]
    assert 1.0 < est.condition_number < 1e8


def test_noisy_estimate_is_consistent_with_its_std(er3a_model, er3a_base) -> None:
    reg, base = er3a_base
    noise = np.array([0.5, 0.5, 0.2, 0.05, 0.05, 0.02])
    q, qd, qdd, tau, theta = _data(er3a_model, reg, noise, seed=1, duration=40.0)
    acc = Accumulator(reg, base)
    acc.add(q, qd, qdd, tau)
    ols = least_squares(acc)
    wls = least_squares(acc, weighted=True)
    mu = base.from_standard(theta)
    for est in (ols, wls):
        z = (est.mu - mu) / est.std
        assert np.sqrt(np.mean(z**2)) < 2.0  # errors are of the size the std devs claim
        assert np.max(np.abs(z)) < 6.0
    # per-joint residual std recovers the injected noise
    np.testing.assert_allclose(ols.residual_std, noise, rtol=0.1)
    # weighting by those std devs helps the weakly loaded joints' parameters
    assert np.sum(((wls.mu - mu) / wls.std) ** 2) < 3 * np.sum(((ols.mu - mu) / wls.std) ** 2)
    assert np.all(wls.relative_std_percent[np.abs(mu) > 1.0] < 100.0)


def test_too_short_data_is_refused(er3a_model, er3a_base) -> None:
    reg, base = er3a_base
    q, qd, qdd, tau, _ = _data(er3a_model, reg)
    acc = Accumulator(reg, base)
    acc.add(q[:5], qd[:5], qdd[:5], tau[:5])
    with pytest.raises(UserError, match="too few"):
        least_squares(acc)


def test_rank_deficient_data_names_a_parameter(er3a_model, er3a_base) -> None:
    reg, base = er3a_base
    q, qd, qdd, tau, _ = _data(er3a_model, reg)
    q[:, 5] = 0.3  # joint 6 never moves
    qd[:, 5] = 0.0
    qdd[:, 5] = 0.0
    acc = Accumulator(reg, base)
    acc.add(q, qd, qdd, tau)
    with pytest.raises(UserError, match=r"(rank deficient|does not excite|not excite).*joint"):
        least_squares(acc)


def test_mismatched_shapes_are_refused(er3a_model, er3a_base) -> None:
    reg, base = er3a_base
    q, qd, qdd, tau, _ = _data(er3a_model, reg)
    with pytest.raises(UserError, match="tau has shape"):
        Accumulator(reg, base).add(q, qd, qdd, tau[:, :5])
