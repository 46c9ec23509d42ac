"""``refresh_friction``: a short run re-fits the friction and keeps the rigid body."""

from __future__ import annotations

import numpy as np

from hofto_hw.identify.excitation import trajectory_from_vector
from hofto_hw.identify.friction_only import refresh_friction
from hofto_hw.identify.pipeline import identify
from hofto_hw.identify.simulate import simulate_tracking


def test_refresh_recovers_changed_viscous_friction(er3a_config, er3a_model) -> None:
    rng = np.random.default_rng(3)
    X = rng.normal(0.0, 0.5, (6, 8)) / np.tile(np.arange(1, 5), 2)
    traj = trajectory_from_vector(np.hstack([er3a_model.home[:, None], X]).ravel(), 6, 5, 5.0)
    sim = er3a_config.simulation.model_copy(deep=True)
    sim.external = []
    sim.torque_noise = sim.velocity_noise = 0.0
    sim.encoder_counts_per_rev = None
    sim.model_error = 0.0
    sim.friction = er3a_config.robot.friction
    day1 = simulate_tracking(er3a_model, sim, traj, rate_hz=200.0)
    pf = identify(er3a_model, [day1.exact], method="ols").parameters
    warmer = np.asarray(sim.friction.viscous) * 0.75  # viscous friction drops by 25 %
    sim2 = sim.model_copy(update={"friction": sim.friction.model_copy(update={"viscous": warmer})})
    day2 = simulate_tracking(er3a_model, sim2, traj, rate_hz=200.0)
    assert not np.allclose(pf.viscous, warmer, rtol=0.05)
    new = refresh_friction(er3a_model, pf, [day2.exact])
    assert np.allclose(new.viscous, warmer, rtol=1e-3, atol=1e-3)
    assert np.allclose(new.coulomb, sim.friction.coulomb, rtol=1e-3, atol=1e-3)
    assert np.array_equal(new.inertial, pf.inertial)  # rigid body kept
    assert "friction-only" in new.method
