"""External torques the simulated world applies to the arm.

A :class:`ExternalTorque` is the sum of components built from ``simulation.external`` in the
config (see :class:`hofto_hw.config.ExternalTorqueConfig`). Joint-space components
(constant, ramp, parabola, sine, chirp) are closed-form in time. Cartesian components map a
force at a frame to joint torques by Jᵀ: ``push`` (a force at the tool with a raised-cosine
profile, as a person's hand) and ``contact`` (a stiff spring-damper wall that pushes back
once the frame crosses it, as an obstacle hit during motion).

Each component is active on [start, start + duration). Time in s, torques in N·m, forces in
N, stiffness in N/m, damping in N·s/m. This is the simulated *world*, not the control tick:
Cartesian components allocate (pinocchio Jacobians).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from hofto_hw.config.models import ExternalTorqueConfig
from hofto_hw.errors import ConfigError
from hofto_hw.model.data import ModelData
from hofto_hw.model.robot import RobotModel


class ExternalTorque:
    """Sum of external-torque components; :meth:`evaluate` gives tau_ext(t, q, qd)."""

    def __init__(self, components: Sequence[ExternalTorqueConfig], model: RobotModel) -> None:
        self.model = model
        self.data = model.create_data()  # own workspace for the Jacobians
        self.n = model.n
        self.components = list(components)
        for i, c in enumerate(self.components):
            _check_component(c, i, model)
        self._out = np.zeros(self.n)

    def evaluate(
        self, t: float, q: np.ndarray, qd: np.ndarray, out: np.ndarray | None = None
    ) -> np.ndarray:
        """External joint torque [N·m], shape (n,), at time ``t`` [s] and state (q, qd)."""
        tau = self._out if out is None else out
        tau.fill(0.0)
        for c in self.components:
            if t < c.start or (c.duration is not None and t >= c.start + c.duration):
                continue
            _add_component(c, t, q, qd, self.data, tau)
        return tau

    def joint_space_only(self) -> bool:
        """True when no component depends on the arm's state (then tau_ext(t) is exact)."""
        return all(c.kind not in ("contact", "push") for c in self.components)


def _vec(values: list[float] | None, n: int) -> np.ndarray:
    return np.zeros(n) if values is None else np.asarray(values, dtype=float)


def _check_component(c: ExternalTorqueConfig, i: int, model: RobotModel) -> None:
    where = f"simulation.external[{i}]"
    needs = {
        "constant": ["amplitude"],
        "ramp": ["amplitude", "slope"],
        "parabola": ["amplitude"],
        "sine": ["amplitude", "frequency"],
        "chirp": ["amplitude", "frequency", "frequency_end", "duration"],
        "contact": ["frame", "wall_point", "wall_normal", "stiffness"],
        "push": ["force", "duration"],
    }[c.kind]
    for name in needs:
        if getattr(c, name) is None:
            raise ConfigError(f"{where}.{name}: required for kind {c.kind!r}")
    if c.frame is not None and not model.pin_model.existFrame(c.frame):
        raise ConfigError(f"{where}.frame: {c.frame!r} is not a frame of {model.name}")


def _add_component(
    c: ExternalTorqueConfig,
    t: float,
    q: np.ndarray,
    qd: np.ndarray,
    data: ModelData,
    tau: np.ndarray,
) -> None:
    n = tau.shape[0]
    tau_rel = t - c.start
    if c.kind == "constant":
        tau += _vec(c.amplitude, n)
    elif c.kind == "ramp":
        tau += _vec(c.amplitude, n) + _vec(c.slope, n) * tau_rel
    elif c.kind == "parabola":
        tau += (
            _vec(c.amplitude, n)
            + _vec(c.slope, n) * tau_rel
            + _vec(c.curvature, n) * tau_rel * tau_rel
        )
    elif c.kind == "sine":
        tau += _vec(c.amplitude, n) * np.sin(
            2.0 * math.pi * _vec(c.frequency, n) * tau_rel + _vec(c.phase, n)
        )
    elif c.kind == "chirp":
        assert c.duration is not None
        f0 = _vec(c.frequency, n)
        f1 = _vec(c.frequency_end, n)
        rate = (f1 - f0) / c.duration
        phase = 2.0 * math.pi * (f0 * tau_rel + 0.5 * rate * tau_rel * tau_rel) + _vec(c.phase, n)
        tau += _vec(c.amplitude, n) * np.sin(phase)
    elif c.kind == "push":
        assert c.duration is not None and c.force is not None
        if c.ramp is None:
            profile = 0.5 * (1.0 - math.cos(2.0 * math.pi * tau_rel / c.duration))
        else:  # trapezoid: a held push
            profile = min(1.0, tau_rel / c.ramp, (c.duration - tau_rel) / c.ramp)
        frame = c.frame or data.model.tool_frame
        J = data.frame_jacobian(q, frame)
        tau += J[:3].T @ (profile * np.asarray(c.force, dtype=float))
    elif c.kind == "contact":
        assert c.frame and c.wall_point and c.wall_normal and c.stiffness
        normal = np.asarray(c.wall_normal, dtype=float)
        normal /= np.linalg.norm(normal)
        x = data.frame_position(q, c.frame)
        penetration = float(normal @ (np.asarray(c.wall_point) - x))
        if penetration <= 0.0:
            return
        J = data.frame_jacobian(q, c.frame)[:3]
        v_n = float(normal @ (J @ qd))
        magnitude = c.stiffness * penetration - (c.damping or 0.0) * v_n
        if magnitude > 0.0:  # a wall pushes, it never pulls
            tau += J.T @ (magnitude * normal)
