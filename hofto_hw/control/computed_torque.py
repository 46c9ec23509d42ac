"""Joint-space computed-torque tracking controller (the demo's "simple controller").

    tau = M(q)·(qdd_d + Kp·(q_d - q) + Kd·(qd_d - qd)) + C(q,qd)·qd + g(q) + f(qd)

on the *nominal* model, with Kp = w², Kd = 2·zeta·w per joint (w [rad/s]). Contact torques
are not compensated: they show as tracking error, which the observers must not mistake for
contact-free motion. Allocation-free.
"""

from __future__ import annotations

import numpy as np

from hofto_hw.model.robot import RobotModel


class ComputedTorque:
    def __init__(self, model: RobotModel, bandwidth: np.ndarray, damping: float = 1.0) -> None:
        w = np.asarray(bandwidth, dtype=float)
        self.model = model
        self.data = model.create_data()
        self.kp = w * w
        self.kd = 2.0 * damping * w
        n = model.n
        self._a = np.zeros(n)
        self._e = np.zeros(n)
        self._tau = np.zeros(n)

    def command(
        self,
        q: np.ndarray,
        qd: np.ndarray,
        q_d: np.ndarray,
        qd_d: np.ndarray,
        qdd_d: np.ndarray,
    ) -> np.ndarray:
        """Motor torque [N·m], shape (n,), a view of an internal buffer."""
        a, e, tau = self._a, self._e, self._tau
        np.subtract(q_d, q, out=e)
        np.multiply(self.kp, e, out=a)
        np.subtract(qd_d, qd, out=e)
        np.multiply(self.kd, e, out=e)
        np.add(a, e, out=a)
        np.add(a, qdd_d, out=a)
        np.dot(self.data.mass_matrix(q), a, out=tau)
        np.add(tau, self.data.nonlinear_effects(q, qd), out=tau)
        np.add(tau, self.data.friction_torque(qd), out=tau)
        return tau
