"""Helpers for observer tests: Levant gains and a held, noise-free simulated arm."""

from __future__ import annotations

import numpy as np

from drivers.sim.plant import Plant
from hofto_hw.config.models import SimulationConfig


def levant_gains(order: int, lipschitz: float, joints: int = 6) -> np.ndarray:
    """Levant's recursive-differentiator gains for differentiator order k = n + 1:
    L_i = lambda_i·Lc^(1/(k+1-i)), lambdas from Levant (2003) (shape (n+2, joints))."""
    lambdas = {2: [3.0, 1.5, 1.1], 3: [5.0, 3.0, 1.5, 1.1], 4: [8.0, 5.0, 3.0, 1.5, 1.1]}
    k = order + 1
    gains = [lam * lipschitz ** (1.0 / (k + 1 - i)) for i, lam in enumerate(lambdas[k])]
    return np.tile(np.array(gains)[:, None], (1, joints))


def levant_powers(order: int) -> np.ndarray:
    k = order + 1
    return np.array([(k - i) / (k - i + 1) for i in range(k)] + [0.0])


def run_hold(model, observer, external, duration=6.0, dt=1e-3, sim=None):
    """Hold the arm at home against ``external`` torques; return t, tau_ext, estimates."""
    sim = sim or SimulationConfig(substeps=4, external=external)
    plant = Plant(model, sim, dt)
    plant.reset(model.home)
    observer.reset(plant.q_meas, plant.qd_meas)
    kp, kd = 3000.0, 120.0
    steps = int(round(duration / dt))
    t = np.zeros(steps)
    truth = np.zeros((steps, model.n))
    est = np.zeros((steps, model.n))
    for k in range(steps):
        q, qd = plant.q_meas, plant.qd_meas
        tau = (
            model.create_data().gravity(q)
            + model.create_data().friction_torque(qd)
            + kp * (model.home - q)
            - kd * qd
        )
        plant.step(tau)
        est[k] = observer.update(plant.q_meas, plant.qd_meas, plant.tau_meas, dt)
        t[k] = plant.t
        truth[k] = plant.tau_ext
    return t, truth, est
