"""Fourier excitation: rest at both ends, limits respected, condition number optimized."""

from __future__ import annotations

import numpy as np
import pytest

from hofto_hw.errors import UserError
from hofto_hw.identify.excitation import (
    ExcitationLimits,
    _initial_guess,
    design_excitation,
    trajectory_from_vector,
)
from hofto_hw.identify.pipeline import nominal_theta


def _limits(model) -> ExcitationLimits:
    h = model.home
    return ExcitationLimits(
        h - 0.8, h + 0.8, np.full(6, 1.5), np.full(6, 6.0), model.limits.torque.copy()
    )


def test_series_derivatives_and_rest() -> None:
    rng = np.random.default_rng(0)
    traj = trajectory_from_vector(rng.normal(size=6 * 9), 6, 5, 8.0)
    t = np.linspace(0.0, 8.0, 4001)
    q, qd, qdd = traj.evaluate(t)
    np.testing.assert_allclose(np.gradient(q, t, axis=0)[5:-5], qd[5:-5], atol=1e-4)
    np.testing.assert_allclose(np.gradient(qd, t, axis=0)[5:-5], qdd[5:-5], atol=1e-3)
    for k in (0, -1):  # starts and ends at rest, periodic
        np.testing.assert_allclose(qd[k], 0.0, atol=1e-12)
        np.testing.assert_allclose(qdd[k], 0.0, atol=1e-9)
    np.testing.assert_allclose(q[0], q[-1], atol=1e-12)


def test_design_respects_limits_and_lowers_condition(er3a_model, er3a_base) -> None:
    reg, base = er3a_base
    lim = _limits(er3a_model)
    traj, cond = design_excitation(
        reg,
        base,
        lim,
        harmonics=4,
        period=8.0,
        n_points=60,
        max_iter=8,
        seed=1,
        nominal=nominal_theta(er3a_model),
    )
    t = np.linspace(0.0, traj.period, 2000)
    q, qd, qdd = traj.evaluate(t)
    assert np.all(q >= lim.position_lower - 1e-6) and np.all(q <= lim.position_upper + 1e-6)
    assert np.all(np.abs(qd) <= lim.velocity + 1e-6)
    assert np.all(np.abs(qdd) <= lim.acceleration + 1e-6)
    # torque limits hold at the optimizer's instants, and nearly between them
    tau = (reg.stack(q[::10], qd[::10], qdd[::10]) @ nominal_theta(er3a_model)).reshape(-1, 6)
    assert np.all(np.abs(tau) <= 1.1 * lim.torque)
    # the optimizer beats a random start of the same size by a clear margin
    m = 2 * 4 - 1
    no_limits = (np.zeros((1, 6 * m)), np.zeros(1))
    rng = np.random.default_rng(1)
    x0 = _initial_guess(6, 4, lim.position_lower, lim.position_upper, *no_limits, rng)
    t_opt = np.linspace(0.0, 8.0, 60, endpoint=False)
    H0 = reg.stack(*trajectory_from_vector(x0, 6, 4, 8.0).evaluate(t_opt))[:, base.columns]
    assert cond < 0.8 * np.linalg.cond(H0)
    assert cond < 1e4


def test_impossible_limits_are_refused(er3a_model, er3a_base) -> None:
    reg, base = er3a_base
    lim = _limits(er3a_model)
    lim.position_upper = lim.position_lower.copy()
    with pytest.raises(UserError, match="position limits"):
        design_excitation(reg, base, lim, max_iter=1)
    with pytest.raises(UserError, match="harmonics"):
        design_excitation(reg, base, _limits(er3a_model), harmonics=1)
