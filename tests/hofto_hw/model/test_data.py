"""Model/data split: results of one workspace survive work on another (defect 3 of issue 7)."""

from __future__ import annotations

import numpy as np


def _sample(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.uniform(-1, 1, n), rng.uniform(-2, 2, n), rng.uniform(-5, 5, n)


def test_friction_result_survives_dynamics_of_another_consumer(er3a_model) -> None:
    model = er3a_model
    q, qd, tau = _sample(model.n, 1)
    q2, qd2, qdd2 = _sample(model.n, 2)
    mine = model.create_data()
    theirs = model.create_data()
    f = mine.friction_torque(qd)
    expected = f.copy()
    # another consumer (e.g. the plant) runs its dynamics in the same tick
    theirs.forward_dynamics(q2, qd2, tau)
    theirs.inverse_dynamics(q2, qd2, qdd2)
    theirs.friction_torque(qd2)
    assert np.array_equal(f, expected)


def test_same_workspace_results_valid_until_same_method_called_again(er3a_model) -> None:
    model = er3a_model
    q, qd, tau = _sample(model.n, 3)
    q2, qd2, qdd2 = _sample(model.n, 4)
    data = model.create_data()
    f = data.friction_torque(qd)
    g = data.gravity(q)
    expected_f, expected_g = f.copy(), g.copy()
    # other methods of the same workspace must not overwrite them (the documented validity)
    data.forward_dynamics(q2, qd2, tau)
    data.inverse_dynamics(q2, qd2, qdd2)
    data.nonlinear_effects(q2, qd2)
    data.coriolis(q2, qd2)
    data.mass_matrix(q2)
    assert np.array_equal(f, expected_f)
    assert np.array_equal(g, expected_g)


def test_tool_jacobian_in_place_matches_pinocchio(er3a_model) -> None:
    import pinocchio as pin

    model = er3a_model
    data = model.create_data()
    q, _, _ = _sample(model.n, 5)
    J = data.tool_jacobian(q)
    ref = pin.computeFrameJacobian(
        model.pin_model,
        pin.Data(model.pin_model),
        q,
        model.tool_frame_id,
        pin.ReferenceFrame.LOCAL_WORLD_ALIGNED,
    )
    assert J.shape == (6, model.n)
    assert np.allclose(J, ref, atol=1e-12)
    assert data.tool_jacobian(q) is J  # the same preallocated buffer every call


def test_workspaces_follow_parameter_changes(er3a_model) -> None:
    model = er3a_model
    data = model.create_data()
    q, _, _ = _sample(model.n, 6)
    g_before = data.gravity(q).copy()
    pi = model.inertial_parameters()
    model.set_inertial_parameters(pi * 1.5)
    assert np.allclose(data.gravity(q), 1.5 * g_before)
