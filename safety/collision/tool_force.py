"""The optional Cartesian limit: |F| of the tool force F explaining one estimate row,
F = (Jᵀ)⁺·tau_ext (damped near singularities, the drag's inverse: hofto_hw/control/wrench.py).
Allocation-free per tick (the Jacobian goes into an owned buffer, the solve is in place)."""

from __future__ import annotations

import math

import numpy as np

from hofto_hw.control.wrench import ToolJacobian


class ToolForce:
    """``check(tau_ext, q)`` -> |F| [N] at the model's tool frame for row ``row`` of
    ``tau_ext`` (k, n) [N·m] at joint positions ``q`` (n,) [rad]."""

    def __init__(self, model: object, row: int) -> None:
        self.jac = ToolJacobian(model)  # type: ignore[arg-type]
        self.row = row
        self.wrench = np.zeros(6)  # (F_x, F_y, F_z, M_x, M_y, M_z) [N, N·m]

    def check(self, tau_ext: np.ndarray, q: np.ndarray) -> float:
        self.jac.update(q)
        w = self.jac.wrench(tau_ext[self.row], self.wrench)
        return math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
