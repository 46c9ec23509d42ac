"""What the schema cannot check alone: the home pose and the demo path against the limits
the loop's limit monitor trips at (safety/limits.monitored_limits: the position range less
``safety.limits.position_margin``, the velocity and torque limits scaled or overridden).

A home outside that band latches a position-limit stop in the first tick; a demo path that
leaves it, or needs more speed or torque than it allows, stops the arm as soon as it gets
there (a path 100 times too large: a torque-limit stop after 54 ms). Both are refused
before anything starts, naming the field, the joint, the value and the limit.

The path's extremes of position and speed after the fade-in are exact (q0 - A·sin φ ± |A|,
|A|·2π/T); the fade-in and the torque (inverse dynamics of the model with the held payload
along the reference, friction included) are sampled at :data:`SAMPLES` points over the
fade-in and the longest period after it. Slow path only: called by ``build`` and
``config check``, never in the tick.
"""

from __future__ import annotations

import math

import numpy as np

from hofto_hw.config.models import SystemConfig
from hofto_hw.control.joint_motion import DemoPath
from hofto_hw.errors import ConfigError
from hofto_hw.model.robot import RobotModel
from safety.limits import monitored_limits

SAMPLES = 2000  # reference samples checked for speed and torque (~20 ms of model calls)


def check_motion(cfg: SystemConfig, model: RobotModel) -> None:
    """Raise ConfigError (one line) if ``robot.home`` or ``run.path`` cannot run inside the
    monitored limits of ``model`` (built with the held payload, see compose.build_model)."""
    lower, upper, vel, tau = monitored_limits(cfg.safety.limits, model.limits)
    margin = cfg.safety.limits.position_margin
    band = f"(the joint range less safety.limits.position_margin = {margin:g} rad)"
    home = model.home
    for j in range(model.n):
        if not lower[j] <= home[j] <= upper[j]:
            raise ConfigError(
                f"robot.home[{j}] = {home[j]:g} rad ({_joint(model, j)}) is outside "
                f"[{lower[j]:g}, {upper[j]:g}] rad {band}: a position-limit stop at once"
            )
    p = cfg.run.path
    if p is None:
        return
    a = np.asarray(p.amplitude, dtype=float)
    period = np.asarray(p.period, dtype=float)
    phase = np.zeros_like(a) if p.phase is None else np.asarray(p.phase, dtype=float)
    w = 2.0 * math.pi / period
    centre = home - a * np.sin(phase)
    for j in range(model.n):
        lo, hi = centre[j] - abs(a[j]), centre[j] + abs(a[j])
        if lo < lower[j] or hi > upper[j]:
            raise ConfigError(
                f"run.path.amplitude[{j}] = {a[j]:g} rad ({_joint(model, j)}) moves the joint "
                f"over [{lo:.4g}, {hi:.4g}] rad about robot.home, outside [{lower[j]:.4g}, "
                f"{upper[j]:.4g}] rad {band}: a position-limit stop"
            )
        if abs(a[j]) * w[j] > vel[j]:
            raise ConfigError(
                f"run.path.amplitude[{j}], period[{j}] = {a[j]:g} rad, {period[j]:g} s "
                f"({_joint(model, j)}) need {abs(a[j]) * w[j]:.4g} rad/s, above the velocity "
                f"limit {vel[j]:.4g} rad/s (safety.limits): a velocity-limit stop"
            )
    _check_sampled(cfg, model, a, period, phase, vel, tau)


def _check_sampled(
    cfg: SystemConfig,
    model: RobotModel,
    a: np.ndarray,
    period: np.ndarray,
    phase: np.ndarray,
    vel: np.ndarray,
    tau_max: np.ndarray,
) -> None:
    """Speed during the fade-in and torque along the path, at SAMPLES points."""
    p = cfg.run.path
    assert p is not None
    path = DemoPath(a, period, phase, p.ramp)
    data = model.create_data()
    n = model.n
    q, qd, qdd, tau = np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n)
    end = p.ramp + float(np.max(period))
    with np.errstate(all="ignore"):
        for t in np.linspace(0.0, end, SAMPLES):
            path.evaluate(float(t), model.home, q, qd, qdd)
            bad = np.flatnonzero(~(np.abs(qd) <= vel))
            if bad.size:
                j = int(bad[0])
                raise ConfigError(
                    f"run.path ({_joint(model, j)}): {abs(qd[j]):.4g} rad/s at t = {t:.3g} s "
                    f"(fade-in over run.path.ramp = {p.ramp:g} s) is above the velocity limit "
                    f"{vel[j]:.4g} rad/s: a velocity-limit stop; lower the amplitude or "
                    "lengthen the period or the ramp"
                )
            data.inverse_dynamics(q, qd, qdd, tau)
            bad = np.flatnonzero(~(np.abs(tau) <= tau_max))
            if bad.size:
                j = int(bad[0])
                raise ConfigError(
                    f"run.path ({_joint(model, j)}): needs {abs(tau[j]):.4g} N·m at t = "
                    f"{t:.3g} s, above the torque limit {tau_max[j]:.4g} N·m (safety.limits; "
                    "payload included): a torque-limit stop; lower the amplitude or lengthen "
                    "the period or the ramp"
                )


def _joint(model: RobotModel, j: int) -> str:
    return f"joint {j + 1}, {model.joint_names[j]}"
