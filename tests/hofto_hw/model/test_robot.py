"""RobotModel: the dynamics identities eq. (1) relies on."""

from __future__ import annotations

import numpy as np
import pytest

from hofto_hw.errors import ModelError
from hofto_hw.model import FrictionParams


def _random_states(model, rng, count=5):
    lo, hi = model.limits.position_lower, model.limits.position_upper
    for _ in range(count):
        yield rng.uniform(lo, hi), rng.normal(0, 1.0, model.n), rng.normal(0, 2.0, model.n)


def test_mass_matrix_symmetric_positive_definite_with_rotor_inertia(er3a_model):
    rng = np.random.default_rng(0)
    base = er3a_model.copy()
    base.rotor_inertia = np.zeros(6)
    for q, _, _ in _random_states(er3a_model, rng):
        M = er3a_model.create_data().mass_matrix(q).copy()
        assert np.allclose(M, M.T)
        assert np.linalg.eigvalsh(M).min() > 0
        diff = M - base.create_data().mass_matrix(q)
        assert np.allclose(diff, np.diag(er3a_model.rotor_inertia))


def test_mdot_equals_c_plus_ct(er3a_model):
    rng = np.random.default_rng(1)
    for q, qd, _ in _random_states(er3a_model, rng):
        C = er3a_model.create_data().coriolis_matrix(q, qd).copy()
        eps = 1e-6
        Md = (
            er3a_model.create_data().mass_matrix(q + eps * qd).copy()
            - er3a_model.create_data().mass_matrix(q - eps * qd)
        ) / (2 * eps)
        assert np.allclose(Md, C + C.T, atol=1e-6)
        assert np.allclose(C @ qd, er3a_model.create_data().coriolis(q, qd))


def test_inverse_and_forward_dynamics_agree(er3a_model):
    rng = np.random.default_rng(2)
    for q, qd, qdd in _random_states(er3a_model, rng):
        tau = er3a_model.create_data().inverse_dynamics(q, qd, qdd).copy()
        expected = (
            er3a_model.create_data().mass_matrix(q) @ qdd
            + er3a_model.create_data().nonlinear_effects(q, qd)
            + er3a_model.create_data().friction_torque(qd)
        )
        assert np.allclose(tau, expected)
        tau_ext = rng.normal(0, 3, 6)
        qdd_back = er3a_model.create_data().forward_dynamics(q, qd, tau - tau_ext, tau_ext)
        assert np.allclose(qdd_back, qdd, atol=1e-9)


def test_gravity_is_the_static_torque(er3a_model):
    q = er3a_model.home
    g = er3a_model.create_data().gravity(q).copy()
    assert np.allclose(er3a_model.create_data().inverse_dynamics(q, np.zeros(6), np.zeros(6)), g)
    assert abs(g[1]) > 1.0  # the shoulder carries the arm
    assert abs(g[0]) < 1e-9  # a vertical base axis carries nothing


def test_friction_eq12_hard_and_smooth_sign():
    f = FrictionParams(np.array([2.0, 1.0]), np.array([0.5, 0.1]), np.array([0.3, -0.2]))
    out = np.zeros(2)
    assert np.allclose(f.torque(np.array([1.0, -2.0]), out), [2.0 + 0.5 + 0.3, -1.0 - 0.2 - 0.2])
    assert np.allclose(f.torque(np.zeros(2), out), [0.3, -0.2])
    smooth = FrictionParams(np.array([2.0]), np.array([0.0]), np.array([0.0]), smooth_velocity=0.1)
    small = smooth.torque(np.array([0.01]), np.zeros(1))[0]
    assert 0.0 < small < 0.25  # tanh(0.1)·2 = 0.199, not the full 2 N·m of a hard sign
    stribeck = FrictionParams(
        np.array([1.0]), np.zeros(1), np.zeros(1), np.array([1.5]), np.array([0.05])
    )
    assert stribeck.torque(np.array([1e-4]), np.zeros(1))[0] == pytest.approx(1.5, rel=1e-3)
    assert stribeck.torque(np.array([1.0]), np.zeros(1))[0] == pytest.approx(1.0, rel=1e-6)


def test_inertial_parameters_round_trip_changes_dynamics(er3a_model):
    q = er3a_model.home
    pi = er3a_model.inertial_parameters()
    assert pi.shape == (60,)
    other = er3a_model.copy()
    scaled = pi.copy()
    scaled[10:20] *= 1.5  # link 2 heavier
    other.set_inertial_parameters(scaled)
    assert np.allclose(other.inertial_parameters(), scaled)
    assert abs(other.create_data().gravity(q)[1]) > abs(er3a_model.create_data().gravity(q)[1])
    with pytest.raises(ModelError, match="expected 60 finite inertial parameters"):
        other.set_inertial_parameters(pi[:10])


def test_tool_jacobian_matches_finite_difference(er3a_model):
    q = er3a_model.home + 0.1
    J = er3a_model.create_data().tool_jacobian(q)
    eps = 1e-7
    for j in range(6):
        dq = np.zeros(6)
        dq[j] = eps
        dp = (
            er3a_model.create_data().tool_pose(q + dq)[0]
            - er3a_model.create_data().tool_pose(q - dq)[0]
        ) / (2 * eps)
        assert np.allclose(J[:3, j], dp, atol=1e-6)


def test_bad_tool_frame(er3a_config):
    from hofto_hw.model import RobotModel

    robot = er3a_config.robot.model_copy(update={"tool_frame": "no_such_frame"})
    with pytest.raises(ModelError, match=r"robot\.tool_frame: frame 'no_such_frame'"):
        RobotModel.from_config(robot)
