"""Physically consistent fit: PSD pseudo-inertias, exact on consistent noise-free data,
and a physical model where plain least squares is not."""

from __future__ import annotations

import numpy as np

from hofto_hw.identify.consistent import consistent_fit, is_consistent, pseudo_inertia
from hofto_hw.identify.estimate import Accumulator, least_squares
from hofto_hw.identify.pipeline import nominal_theta
from hofto_hw.identify.regressor import split_standard

from .conftest import smooth_motion


def test_pseudo_inertia_of_a_real_body_is_psd(er3a_model) -> None:
    pi = er3a_model.inertial_parameters()
    assert is_consistent(pi)
    bad = pi.copy()
    bad[0] = -1.0  # negative mass
    assert not is_consistent(bad)
    J = pseudo_inertia(pi[:10])
    assert J[3, 3] == pi[0] and np.allclose(J, J.T)


def test_noise_free_consistent_fit_recovers_base(er3a_model, er3a_base) -> None:
    reg, base = er3a_base
    _, q, qd, qdd = smooth_motion(6, 20.0, 100.0, seed=2)
    theta = nominal_theta(er3a_model)
    tau = (reg.stack(q, qd, qdd) @ theta).reshape(q.shape)
    acc = Accumulator(reg, base)
    acc.add(q, qd, qdd, tau)
    prior = theta.copy()
    prior[:60] *= 1.5  # the prior is wrong: only unseen directions may follow it
    fitted = consistent_fit(acc.combined(), base, prior, 6)
    mu = base.from_standard(theta)
    assert np.linalg.norm(base.from_standard(fitted) - mu) / np.linalg.norm(mu) < 1e-6
    assert is_consistent(fitted[:60])


def test_consistent_when_least_squares_is_not(er3a_model, er3a_base) -> None:
    reg, base = er3a_base
    _, q, qd, qdd = smooth_motion(6, 4.0, 50.0, seed=4)
    theta = nominal_theta(er3a_model)
    rng = np.random.default_rng(0)
    tau = (reg.stack(q, qd, qdd) @ theta).reshape(q.shape)
    tau += rng.normal(0.0, 2.0, tau.shape)  # heavy noise, short record
    acc = Accumulator(reg, base)
    acc.add(q, qd, qdd, tau)
    ols = least_squares(acc)
    naive = base.to_standard(ols.mu, np.zeros_like(theta))
    assert not is_consistent(naive[:60])
    fitted = consistent_fit(acc.combined(), base, theta, 6)
    parts = split_standard(fitted, 6)
    assert is_consistent(parts["inertial"])
    assert np.all(parts["rotor_inertia"] >= -1e-9)
    assert np.all(parts["coulomb"] >= -1e-9) and np.all(parts["viscous"] >= -1e-9)
