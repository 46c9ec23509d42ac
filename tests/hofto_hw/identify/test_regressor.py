"""H_s(q, qd, qdd)·theta_s must equal the model's inverse dynamics (rigid body, rotor,
friction), for both arms and with the optional Stribeck columns."""

from __future__ import annotations

import numpy as np
import pytest

from hofto_hw.errors import UserError
from hofto_hw.identify.pipeline import nominal_theta
from hofto_hw.identify.regressor import Regressor, split_standard, standard_names
from hofto_hw.model.friction import FrictionParams


@pytest.mark.parametrize("which", ["ur10e_model", "er3a_model"])
def test_regressor_reproduces_inverse_dynamics(which: str, request: pytest.FixtureRequest) -> None:
    model = request.getfixturevalue(which).copy()
    n = model.n
    rng = np.random.default_rng(3)
    model.rotor_inertia = rng.uniform(0.01, 0.5, n)
    model.friction = FrictionParams(
        rng.uniform(0.5, 5, n), rng.uniform(0.5, 5, n), rng.normal(0, 1, n), smooth_velocity=0.02
    )
    reg = Regressor(model.pin_model, 0.02)
    q, qd, qdd = (rng.uniform(-2, 2, (30, n)) for _ in range(3))
    qd[0] = 0.0  # standstill: friction is the bias alone
    H = reg.stack(q, qd, qdd)
    assert H.shape == (30 * n, 14 * n)
    tau = (H @ nominal_theta(model)).reshape(30, n)
    expected = np.array(
        [model.create_data().inverse_dynamics(q[k], qd[k], qdd[k]).copy() for k in range(30)]
    )
    np.testing.assert_allclose(tau, expected, rtol=1e-10, atol=1e-9)


def test_stribeck_columns_match_friction_model(ur10e_model) -> None:
    model = ur10e_model.copy()
    n = model.n
    vs = np.full(n, 0.05)
    model.friction = FrictionParams(
        np.full(n, 2.0), np.full(n, 1.0), np.zeros(n), np.full(n, 3.0), vs, smooth_velocity=0.01
    )
    reg = Regressor(model.pin_model, 0.01, vs)
    rng = np.random.default_rng(0)
    q = rng.uniform(-2, 2, (20, n))
    qd = rng.uniform(-0.1, 0.1, (20, n))
    qdd = rng.uniform(-1, 1, (20, n))
    theta = nominal_theta(model, stribeck=True)
    assert theta.size == 15 * n
    assert split_standard(theta, n)["stribeck_gap"] == pytest.approx(np.ones(n))
    tau = (reg.stack(q, qd, qdd) @ theta).reshape(20, n)
    expected = np.array(
        [model.create_data().inverse_dynamics(q[k], qd[k], qdd[k]).copy() for k in range(20)]
    )
    np.testing.assert_allclose(tau, expected, rtol=1e-10, atol=1e-9)


@pytest.mark.parametrize("passive", [False, True])
def test_every_friction_block_matches_the_model_with_its_memory(ur10e_model, passive) -> None:
    """Stribeck, held (two-sided and passive) and quadratic columns together: H_s·theta_s is
    the model's inverse dynamics over a sequence, the held memory running in both."""
    model = ur10e_model.copy()
    n = model.n
    rng = np.random.default_rng(5)
    vs = rng.uniform(0.03, 0.1, n)
    model.friction = FrictionParams(
        rng.uniform(0.5, 5, n),
        rng.uniform(0.5, 5, n),
        rng.normal(0, 1, n),
        rng.uniform(5.5, 8, n),
        vs,
        smooth_velocity=0.02,
        held=rng.uniform(0.2, 2.5, n),
        held_velocity=0.01,
        quadratic=rng.uniform(-0.5, 0.5, n),
        held_passive=passive,
    )
    reg = Regressor(model.pin_model, 0.02, vs, 0.01, quadratic=True, held_passive=passive)
    N = 60
    q, qdd = rng.uniform(-2, 2, (N, n)), rng.uniform(-1, 1, (N, n))
    qd = np.cumsum(rng.normal(0, 0.006, (N, n)), axis=0)  # creeps through the held band
    theta = nominal_theta(model, stribeck=True, held=True, quadratic=True)
    tau = (reg.stack(q, qd, qdd) @ theta).reshape(N, n)
    data = model.create_data()
    expected = np.array([data.inverse_dynamics(q[k], qd[k], qdd[k]).copy() for k in range(N)])
    np.testing.assert_allclose(tau, expected, rtol=1e-10, atol=1e-9)
    H = reg.stack(q, qd, qdd).reshape(N, n, -1)
    held_cols = H[:, :, 15 * n : 16 * n]
    assert np.any(held_cols != 0.0) and np.any(held_cols.sum(axis=2) * qd < 0.0) != passive


def test_names_and_shape_errors(ur10e_model) -> None:
    names = standard_names(ur10e_model.joint_names)
    assert len(names) == 84 and names[0] == "shoulder_pan_joint.m"
    assert names[60] == "shoulder_pan_joint.Ia" and names[-1] == "wrist_3_joint.B"
    reg = Regressor(ur10e_model.pin_model)
    with pytest.raises(UserError, match="shape"):
        reg.stack(np.zeros((5, 5)), np.zeros((5, 5)), np.zeros((5, 5)))
    with pytest.raises(UserError, match="stribeck_velocity"):
        Regressor(ur10e_model.pin_model, 0.0, np.zeros(6))
