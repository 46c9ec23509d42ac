"""The simulated arm: physics, scenarios, measurement model."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.sim.plant import Plant, perturbed_model
from drivers.sim.scenarios import ExternalTorque
from hofto_hw.config.models import ExternalTorqueConfig, SimulationConfig
from hofto_hw.errors import ConfigError


def test_gravity_compensated_arm_stays_and_pushed_arm_accelerates(er3a_model):
    from hofto_hw.model import FrictionParams

    er3a_model = er3a_model.copy()
    er3a_model.friction = FrictionParams.zeros(6)  # so the push's acceleration is M⁻¹·tau
    plant = Plant(er3a_model, SimulationConfig(substeps=4), 1e-3)
    plant.reset(er3a_model.home)
    for _ in range(200):
        plant.step(er3a_model.create_data().gravity(plant.q))
    assert np.abs(plant.q - er3a_model.home).max() < 1e-9
    tau = er3a_model.create_data().gravity(plant.q).copy()
    tau[0] += 2.0
    plant.step(tau)
    M = er3a_model.create_data().mass_matrix(plant.q)
    expected = np.linalg.solve(M, np.eye(6)[0] * 2.0)
    assert plant.qdd[0] == pytest.approx(expected[0], rel=1e-3)


def test_external_torque_kinds(er3a_model):
    comps = [
        ExternalTorqueConfig(kind="ramp", start=1.0, amplitude=[1] * 6, slope=[2] * 6),
        ExternalTorqueConfig(
            kind="parabola", start=0.0, duration=0.5, amplitude=[0] * 6, curvature=[4] * 6
        ),
        ExternalTorqueConfig(kind="sine", start=0.0, amplitude=[3] * 6, frequency=[1] * 6),
    ]
    ext = ExternalTorque(comps, er3a_model)
    q = er3a_model.home
    zero = np.zeros(6)
    assert ext.evaluate(0.25, q, zero)[0] == pytest.approx(4 * 0.0625 + 3.0)
    assert ext.evaluate(2.0, q, zero)[0] == pytest.approx(1 + 2 * 1.0 + 0.0, abs=1e-9)
    assert ext.joint_space_only()


def test_push_maps_force_by_jacobian_transpose(er3a_model):
    push = ExternalTorqueConfig(kind="push", start=0.0, duration=2.0, force=(0.0, 0.0, -30.0))
    ext = ExternalTorque([push], er3a_model)
    q = er3a_model.home
    tau = ext.evaluate(1.0, q, np.zeros(6)).copy()  # peak of the raised cosine
    J = er3a_model.create_data().tool_jacobian(q)[:3]
    np.testing.assert_allclose(tau, J.T @ np.array([0.0, 0.0, -30.0]))
    assert np.allclose(ext.evaluate(2.5, q, np.zeros(6)), 0.0)


def test_contact_wall_only_pushes(er3a_model):
    q = er3a_model.home
    x = er3a_model.create_data().tool_pose(q)[0]
    wall = ExternalTorqueConfig(
        kind="contact",
        frame="tool0",
        wall_point=tuple(x + [0.01, 0, 0]),
        wall_normal=(-1.0, 0.0, 0.0),
        stiffness=1e4,
    )
    inside = ExternalTorque([wall], er3a_model).evaluate(0.0, q, np.zeros(6)).copy()
    assert np.allclose(inside, 0.0)  # the wall is 1 cm ahead: no contact yet
    wall2 = wall.model_copy(update={"wall_point": tuple(x - [0.01, 0, 0])})
    tau = ExternalTorque([wall2], er3a_model).evaluate(0.0, q, np.zeros(6))
    J = er3a_model.create_data().tool_jacobian(q)[:3]
    np.testing.assert_allclose(tau, J.T @ np.array([-100.0, 0.0, 0.0]), atol=1e-9)


def test_missing_scenario_field_is_named(er3a_model):
    with pytest.raises(ConfigError, match=r"simulation.external\[0\].frequency: required"):
        ExternalTorque([ExternalTorqueConfig(kind="sine", amplitude=[1] * 6)], er3a_model)


def test_quantisation_noise_and_determinism(er3a_model):
    sim = SimulationConfig(
        seed=3, encoder_counts_per_rev=[2**16] * 6, torque_noise=0.1, velocity_noise=0.01
    )
    a, b = Plant(er3a_model, sim, 1e-3), Plant(er3a_model, sim, 1e-3)
    res = 2 * np.pi / 2**16
    for p in (a, b):
        for _ in range(10):
            p.step(er3a_model.create_data().gravity(p.q))
    np.testing.assert_array_equal(a.tau_meas, b.tau_meas)
    steps = a.q_meas / res
    assert np.allclose(steps, np.round(steps))
    assert 0 < np.abs(a.tau_meas - a.tau_applied).max() < 1.0


def test_model_error_perturbs_but_keeps_physics(er3a_model):
    true = perturbed_model(er3a_model, 0.1, np.random.default_rng(0))
    pi0, pi1 = er3a_model.inertial_parameters(), true.inertial_parameters()
    rel = np.abs(pi1 - pi0)[::10] / pi0[::10]  # masses
    assert rel.max() > 0.01 and rel.max() < 0.25
    assert np.linalg.eigvalsh(true.create_data().mass_matrix(er3a_model.home)).min() > 0


def test_plant_holds_friction_of_the_last_direction(er3a_config, er3a_model):
    """With held friction the torque that holds the arm still depends on the direction it
    last moved in (hysteresis); without it, it does not."""
    from hofto_hw.config.models import FrictionConfig

    def holding(held: list[float] | None, direction: float) -> tuple[np.ndarray, np.ndarray]:
        fr = FrictionConfig(coulomb=[0.0] * 6, viscous=[0.5] * 6, held=held, held_velocity=0.01)
        plant = Plant(er3a_model, SimulationConfig(substeps=2, friction=fr), 1e-3)
        plant.reset(er3a_model.home, qd0=np.full(6, 0.2 * direction))
        data = plant.true_model.create_data()
        m = np.diag(data.mass_matrix(er3a_model.home)).copy()
        f = np.zeros(6)
        for k in range(1500):  # a PD brings the arm back to home (last motion: -direction)
            pd = 400.0 * m * (er3a_model.home - plant.q) - 40.0 * m * plant.qd
            plant.step(data.gravity(plant.q) + pd)
            if k >= 1000:  # at rest tau = g + f: the PD holds against the friction
                f += (plant.tau_applied - data.gravity(plant.q)) / 500
        assert np.abs(plant.q - er3a_model.home).max() < 0.01
        return plant.data.friction_state.copy(), f

    held = np.array([3.0, 2.0, 1.5, 0.6, 0.5, 0.4])
    s_pos, f_pos = holding(held.tolist(), 1.0)
    s_neg, f_neg = holding(held.tolist(), -1.0)
    assert s_pos.tolist() == [-1.0] * 6 and s_neg.tolist() == [1.0] * 6
    assert np.all(f_neg - f_pos > 0.4 * held)  # the held friction of the last direction
    _, g_pos = holding(None, 1.0)
    _, g_neg = holding(None, -1.0)
    assert np.allclose(g_pos - g_neg, 0.0, atol=0.01)
