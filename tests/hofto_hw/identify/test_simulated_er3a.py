"""Acceptance on the simulated ER3A-class arm (drivers.sim.Plant, configs/er3a.yaml).

- noise-free excitation data: the true base parameters come back to relative error < 1e-6;
- realistic noise and quantisation: on a different trajectory the identified model's relative
  RMSE is within 1.5x of the true model's on the same noisy data.
"""

from __future__ import annotations

import numpy as np
import pytest

from hofto_hw.identify.data import condition
from hofto_hw.identify.excitation import trajectory_from_vector
from hofto_hw.identify.pipeline import Samples, identify, nominal_theta
from hofto_hw.identify.simulate import simulate_tracking
from hofto_hw.identify.validation import errors, predict
from hofto_hw.model.parameters import apply_parameters


def _trajectory(model, seed: int, period: float = 10.0):
    """A random 5-harmonic excitation around home within about ±0.8 rad."""
    rng = np.random.default_rng(seed)
    X = rng.normal(0.0, 0.5, (6, 8)) / np.tile(np.arange(1, 5), 2)
    X = np.hstack([model.home[:, None], X])
    return trajectory_from_vector(X.ravel(), 6, 5, period)


def test_noise_free_recovers_true_base_parameters(er3a_config, er3a_model) -> None:
    sim = er3a_config.simulation.model_copy(deep=True)
    sim.external = []
    sim.torque_noise = 0.0
    sim.velocity_noise = 0.0
    sim.encoder_counts_per_rev = None
    sim.friction = er3a_config.robot.friction  # the model's friction structure (no Stribeck)
    run = simulate_tracking(er3a_model, sim, _trajectory(er3a_model, 0), rate_hz=200.0)
    result = identify(er3a_model, [run.exact], method="ols")
    true = result.base.from_standard(nominal_theta(run.plant.true_model))
    assert not np.allclose(true, result.base.from_standard(nominal_theta(er3a_model)))
    rel = np.linalg.norm(result.ols.mu - true) / np.linalg.norm(true)
    assert rel < 1e-6
    worst = np.max(np.abs(result.ols.mu - true) / np.maximum(np.abs(true), 1e-3))
    assert worst < 1e-6


@pytest.mark.slow
def test_noisy_identification_predicts_like_the_true_model(er3a_config, er3a_model) -> None:
    sim = er3a_config.simulation.model_copy(deep=True)
    sim.external = []  # identification runs have no contact
    assert sim.torque_noise > 0 and sim.encoder_counts_per_rev is not None
    vs = np.asarray(sim.friction.stribeck_velocity)  # structure known, values identified
    train = simulate_tracking(er3a_model, sim, _trajectory(er3a_model, 0), 500.0, 20.0)
    rec = condition(train.measured, 10.0, trim=False, filter_torque=False)
    result = identify(
        er3a_model,
        [Samples(rec.q, rec.qd, rec.qdd, rec.tau, rec.source)],
        method="consistent",
        stribeck_velocity=vs,
    )
    identified = er3a_model.copy()
    apply_parameters(identified, result.parameters)

    test = simulate_tracking(er3a_model, sim, _trajectory(er3a_model, 7), 500.0, 10.0)
    rec2 = condition(test.measured, 10.0, trim=False, filter_torque=False)
    e_id = errors(rec2.tau, predict(identified, rec2.q, rec2.qd, rec2.qdd))
    e_true = errors(rec2.tau, predict(test.plant.true_model, rec2.q, rec2.qd, rec2.qdd))
    ratio = e_id.relative_percent / e_true.relative_percent
    assert np.all(ratio < 1.5), f"identified/true relative RMSE ratio {ratio.round(2)}"
    # and the nominal (unidentified) model is clearly worse on at least one joint
    e_nom = errors(rec2.tau, predict(er3a_model, rec2.q, rec2.qd, rec2.qdd))
    assert np.max(e_nom.relative_percent / e_true.relative_percent) > 1.5
