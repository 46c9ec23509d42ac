"""Plant: the simulated "true" arm behind the simulated drives.

The plant integrates pinocchio forward dynamics (ABA) of a *true* arm whose link inertial
parameters and rotor inertias may differ from the nominal model by a configurable relative
amount, with its own friction (Coulomb, viscous, bias, Stribeck, quadratic, and held friction
with memory in its passive form, the held sign kept in the plant's own model workspace) and
external torques from scripted scenarios. It measures like a drive does: encoder-quantised
position, noisy velocity, noisy motor torque.

Integration: semi-implicit (symplectic) Euler with ``substeps`` per tick; the motor torque
is held over the tick (zero-order hold, as a drive's torque loop does between PDO updates)
while the external torque and friction are re-evaluated every substep. Seeded and
deterministic: the same config and inputs give the same samples.

Units: s, rad, rad/s, rad/s², N·m. Arrays have shape (n,).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from drivers.sim.scenarios import ExternalTorque
from hofto_hw.config.models import SimulationConfig
from hofto_hw.model.friction import FrictionParams
from hofto_hw.model.robot import RobotModel


def perturbed_model(
    model: RobotModel, relative_error: float, rng: np.random.Generator
) -> RobotModel:
    """A copy of ``model`` whose links differ by about ``relative_error`` (1-sigma).

    Per link: mass scaled by (1 + e·u), centre of mass moved by e·(|c| + 1 cm)·u (per axis),
    rotational inertia about the centre of mass scaled by (1 + e·u); rotor inertia scaled by
    (1 + e·u); u ~ N(0, 1) clipped to ±2. Scaling keeps every link physically consistent.
    """
    true = model.copy()
    if relative_error <= 0.0:
        return true
    for j in range(1, true.n + 1):
        inertia = true.pin_model.inertias[j]
        u = np.clip(rng.standard_normal(5), -2.0, 2.0)
        mass = inertia.mass * (1.0 + relative_error * u[0])
        com = inertia.lever + relative_error * (np.abs(inertia.lever) + 0.01) * u[1:4]
        rot = inertia.inertia * (1.0 + relative_error * u[4])
        true.pin_model.inertias[j] = pin.Inertia(max(mass, 1e-6), com, rot)
    ia = true.rotor_inertia
    u = np.clip(rng.standard_normal(true.n), -2.0, 2.0)
    true.rotor_inertia = np.maximum(ia * (1.0 + relative_error * u), 0.0)
    return true


class Plant:
    """Simulated arm. ``step(tau)`` advances one tick of ``dt`` seconds.

    State (true): ``t`` [s], ``q``, ``qd``, ``qdd``, ``tau_ext`` (external torque at the end
    of the last tick), ``tau_applied`` (motor torque of the last tick).
    Measurements (what a drive reports): ``q_meas``, ``qd_meas``, ``tau_meas``.
    """

    def __init__(
        self,
        model: RobotModel,
        sim: SimulationConfig | None = None,
        dt: float = 1e-3,
    ) -> None:
        sim = sim if sim is not None else SimulationConfig()
        if dt <= 0.0:
            raise ValueError(f"dt must be > 0 s, got {dt}")
        self.config = sim
        self.dt = float(dt)
        self.substeps = sim.substeps
        self.h = self.dt / self.substeps
        self.rng = np.random.default_rng(sim.seed)
        self.true_model = perturbed_model(model, sim.model_error, self.rng)
        if sim.friction is not None:
            self.true_model.friction = FrictionParams.from_config(sim.friction, model.n)
            # a simulated force must be passive: the held term only resists motion
            self.true_model.friction.held_passive = True
        self.n = model.n
        self.data = self.true_model.create_data()  # the plant's own workspace
        self.external = ExternalTorque(sim.external, self.true_model)
        cpr = sim.encoder_counts_per_rev
        self._resolution = None if cpr is None else 2.0 * np.pi / np.asarray(cpr, dtype=float)
        n = self.n
        self.t = 0.0
        self.q = np.zeros(n)
        self.qd = np.zeros(n)
        self.qdd = np.zeros(n)
        self.tau_ext = np.zeros(n)
        self.tau_applied = np.zeros(n)
        self.q_meas = np.zeros(n)
        self.qd_meas = np.zeros(n)
        self.tau_meas = np.zeros(n)
        self._noise = np.zeros(n)
        self.reset(model.home)

    def reset(self, q0: np.ndarray, qd0: np.ndarray | None = None, t0: float = 0.0) -> None:
        """Put the arm at rest (or at ``qd0``) in ``q0`` at time ``t0``; measure."""
        self.t = float(t0)
        self.q[:] = q0
        self.qd[:] = 0.0 if qd0 is None else qd0
        self.qdd.fill(0.0)
        self.tau_applied.fill(0.0)
        self.data.reset_friction_state()
        self.external.evaluate(self.t, self.q, self.qd, out=self.tau_ext)
        self._measure()

    def step(self, tau: np.ndarray) -> None:
        """Advance one tick with motor torque ``tau`` [N·m] (joint side) held constant."""
        np.copyto(self.tau_applied, tau)
        h = self.h
        data = self.data
        for _ in range(self.substeps):
            self.external.evaluate(self.t, self.q, self.qd, out=self.tau_ext)
            data.forward_dynamics(self.q, self.qd, self.tau_applied, self.tau_ext, out=self.qdd)
            self.qd += h * self.qdd
            self.q += h * self.qd
            self.t += h
        self.external.evaluate(self.t, self.q, self.qd, out=self.tau_ext)
        self._measure()

    def _measure(self) -> None:
        cfg = self.config
        if self._resolution is None:
            np.copyto(self.q_meas, self.q)
        else:
            np.divide(self.q, self._resolution, out=self.q_meas)
            np.floor(self.q_meas, out=self.q_meas)
            np.multiply(self.q_meas, self._resolution, out=self.q_meas)
        np.copyto(self.qd_meas, self.qd)
        if cfg.velocity_noise > 0.0:
            self.qd_meas += self.rng.normal(0.0, cfg.velocity_noise, self.n)
        np.copyto(self.tau_meas, self.tau_applied)
        if cfg.torque_noise > 0.0:
            self.tau_meas += self.rng.normal(0.0, cfg.torque_noise, self.n)
