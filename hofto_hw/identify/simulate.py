"""Excitation runs on the simulated arm (drivers.sim.Plant), for tests, benchmarks and demos.

The plant follows a trajectory under computed-torque control with the nominal model plus a
PD term on the measurements. Each tick gives a measured sample (encoder-quantised q, noisy
qd and tau, as configured) and an exact one: q, qd at the start of the tick, the motor
torque held over it and the true acceleration the plant's forward dynamics give there.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from hofto_hw.config.models import SimulationConfig
from hofto_hw.identify.data import Recording
from hofto_hw.identify.excitation import FourierTrajectory
from hofto_hw.identify.pipeline import Samples

if TYPE_CHECKING:
    from drivers.sim.plant import Plant
    from hofto_hw.model.robot import RobotModel


@dataclass
class SimulatedRun:
    """``measured``: a Recording as a logger would give it (t (N,), q, qd, tau (N, n));
    ``exact``: true q, qd, qdd and applied tau, (N, n) each; ``plant``: the simulator."""

    measured: Recording
    exact: Samples
    plant: Plant


def simulate_tracking(
    model: RobotModel,
    sim: SimulationConfig | None,
    trajectory: FourierTrajectory,
    rate_hz: float = 200.0,
    duration: float | None = None,
    kp: float = 400.0,
    kd: float = 40.0,
) -> SimulatedRun:
    """Run ``trajectory`` for ``duration`` [s] (default one period) at ``rate_hz`` ticks.

    Gains kp [1/s²], kd [1/s] scale the diagonal of M(q) at home (computed-torque PD).
    """
    from drivers.sim.plant import Plant

    dt = 1.0 / rate_hz
    plant = Plant(model, sim, dt)
    T = trajectory.period if duration is None else duration
    t = np.arange(0.0, T, dt)
    q_des, qd_des, qdd_des = trajectory.evaluate(t)
    N, n = t.size, model.n
    plant.reset(q_des[0])
    data = model.create_data()
    Mdiag = np.diag(data.mass_matrix(model.home)).copy()
    Kp, Kd = kp * Mdiag, kd * Mdiag
    out = {k: np.zeros((N, n)) for k in ("q", "qd", "tau", "applied", "qe", "qde", "qdde")}
    tm = np.zeros(N)
    tau = np.zeros(n)
    true = plant.true_model.create_data()
    for k in range(N):
        tm[k] = plant.t
        out["q"][k] = plant.q_meas
        out["qd"][k] = plant.qd_meas
        data.inverse_dynamics(q_des[k], qd_des[k], qdd_des[k], out=tau)
        tau += Kp * (q_des[k] - plant.q_meas) + Kd * (qd_des[k] - plant.qd_meas)
        out["qe"][k] = plant.q
        out["qde"][k] = plant.qd
        true.forward_dynamics(plant.q, plant.qd, tau, plant.tau_ext, out=out["qdde"][k])
        out["applied"][k] = tau
        plant.step(tau)
        out["tau"][k] = plant.tau_meas
    rec = Recording(
        t=tm,
        q=out["q"],
        qd=out["qd"],
        tau=out["tau"],
        source=f"simulated {model.name}",
        rows=np.arange(1, N + 1, dtype=np.int64),
    )
    exact = Samples(out["qe"], out["qde"], out["qdde"], out["applied"], rec.source)
    return SimulatedRun(rec, exact, plant)
