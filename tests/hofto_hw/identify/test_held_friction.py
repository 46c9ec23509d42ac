"""The simulated plant has held friction; identification with the held term recovers it."""

from __future__ import annotations

import numpy as np

from hofto_hw.identify.excitation import trajectory_from_vector
from hofto_hw.identify.pipeline import identify, nominal_theta
from hofto_hw.identify.simulate import simulate_tracking


def _trajectory(model, seed: int, period: float = 6.0):
    rng = np.random.default_rng(seed)
    X = rng.normal(0.0, 0.5, (6, 8)) / np.tile(np.arange(1, 5), 2)
    X = np.hstack([model.home[:, None], X])
    return trajectory_from_vector(X.ravel(), 6, 5, period)


def test_identification_recovers_held_friction(er3a_config, er3a_model) -> None:
    held = [3.0, 2.0, 1.5, 0.6, 0.5, 0.4]
    sim = er3a_config.simulation.model_copy(deep=True)
    sim.external = []
    sim.torque_noise = 0.0
    sim.velocity_noise = 0.0
    sim.encoder_counts_per_rev = None
    sim.friction = er3a_config.robot.friction.model_copy(
        update={"held": held, "held_velocity": 0.01}
    )
    run = simulate_tracking(er3a_model, sim, _trajectory(er3a_model, 0), rate_hz=200.0)
    assert run.plant.true_model.friction.held.tolist() == held
    # the held sign at the end of the run is the plant's memory, kept in its workspace
    assert np.any(run.plant.data.friction_state != 0.0)

    result = identify(er3a_model, [run.exact], method="ols", held_velocity=0.01, held_passive=True)
    true = result.base.from_standard(nominal_theta(run.plant.true_model, held=True))
    rel = np.linalg.norm(result.ols.mu - true) / np.linalg.norm(true)
    assert rel < 1e-6
    names = result.base.names
    got = [result.ols.mu[names.index(f"{j}.H")] for j in er3a_model.joint_names]
    assert np.allclose(got, held, rtol=1e-4, atol=1e-6)
    assert np.allclose(result.parameters.held, held, rtol=1e-4, atol=1e-6)

    # a model without the held term cannot explain these data as well
    plain = identify(er3a_model, [run.exact], method="ols")
    assert np.all(plain.ols.rmse >= result.ols.rmse)
    assert np.max(plain.ols.rmse) > 1e-3
