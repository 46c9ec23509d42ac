"""Discrete-time stability of an observer's gains at the rate it will run.

:func:`check_observer` raises :class:`~hofto_hw.errors.ConfigError` with one line naming
``observers.<name>.<field>``, the joint, the value, the rate and (where a closed form exists)
the largest stable value. Per type:

- momentum: the residual obeys r_k = (1 - K·dt)·r_{k-1} + K·dt·tau_ext (forward Euler), stable
  iff 0 < K·dt < 2: K < 2·rate. (200 1/s on 100 Hz data gave 1e83 N·m.)
- eso: the error of explicit Euler with ``substeps`` m evolves by (I + h·A)^m per tick,
  h = dt/m, A the companion matrix of s³ + k1·s² + k2·s + k3. Refused when the error grows by
  more than :data:`GROWTH_LIMIT` per second (spectral radius ρ: ρ^(m·rate) > 1.1). Slower growth
  is accepted on purpose: the paper's (5, 40, 200) has k1·k2 = k3, poles on the imaginary axis,
  and Euler makes them drift outward by ρ = 1 + 2.0e-5 per tick at 1 kHz (2 %/s, measured
  x1.8 in 60 s on a unit double integrator), but by 22 %/s at 100 Hz (x1e4 in 60 s): refused
  there. With scaled gains (s·k1, s²·k2, s³·k3) every pole λ scales by s, so ρ < 1 iff
  s < min(-2·Re λ / (h·|λ|²)): that bound is printed.
- dob: the low-pass is discretised exactly for a held input, w += (1 - exp(-g·dt))·(u - w);
  the factor lies in (0, 1) for every g > 0 and the estimate stays bounded (its coefficient
  (1 - a)·g = g·exp(-g·dt) -> 0): stable for any positive cutoff. Nothing to refuse.
- direct: a first-order low-pass with alpha = dt/(dt + 1/(2π·fc)) in (0, 1): always stable.
- sta, hofto: nonlinear, no closed form. Measured: the per-joint core (HoftoCore; STA through
  Remark 7's equivalence, powers 1/2, 1/2, 0) runs on a unit double integrator at the rate
  from a perturbed start (q error 0.01 rad, qd 0.1 rad/s, x3 1 rad/s²) for
  :data:`SETTLE_TIME`; refused when any of z1..z3 is non-finite or leaves
  :data:`BOUND` (10x the largest perturbation) in the second half; at most
  :data:`MAX_STEPS` steps whatever the rate (its cost is bounded). Stable gains settle or
  chatter below the perturbation (the paper's HOFTO gains at 1 kHz: |z3| <= 0.02 rad/s²;
  at 100 Hz: 1.4); unstable ones grow without bound (HOFTO gains x5 at 100 Hz: 30, x30: 4e3).
"""

from __future__ import annotations

import math

import numpy as np

from hofto_hw.config.models import (
    EsoConfig,
    HoftoConfig,
    MomentumConfig,
    ObserverConfig,
    StaConfig,
)
from hofto_hw.errors import ConfigError
from hofto_hw.model.robot import RobotModel
from hofto_hw.observers.eso import error_matrices
from hofto_hw.observers.hofto import HoftoCore

GROWTH_LIMIT = 1.1  # largest accepted error growth per second of a linear observer
SETTLE_TIME = 2.0  # s, simulated time of the nonlinear check
BOUND = 10.0  # largest accepted |z1..z3| error in the second half of the nonlinear check
PERTURBATION = (0.01, 0.1, 1.0)  # initial errors of z1 [rad], z2 [rad/s], z3 [rad/s²]
#: most steps of the nonlinear check, whatever the rate: SETTLE_TIME at 10 kHz (loop.rate_hz's
#: bound); a faster rate (a recording's sample rate) is checked over fewer seconds
MAX_STEPS = 20_000


def check_observer(name: str, cfg: ObserverConfig, model: RobotModel, rate_hz: float) -> None:
    """Raise ConfigError if observer ``name``'s gains are unstable at ``rate_hz`` [Hz]."""
    if not (math.isfinite(rate_hz) and rate_hz > 0.0):
        raise ConfigError(f"rate {rate_hz} Hz: must be finite and > 0")
    where = f"observers.{name}"
    if isinstance(cfg, MomentumConfig):
        _check_momentum(where, cfg, model, rate_hz)
    elif isinstance(cfg, EsoConfig):
        _check_eso(where, cfg, model, rate_hz)
    elif isinstance(cfg, StaConfig):
        gains = np.array([cfg.l1, cfg.l2, cfg.l3], dtype=float)
        core = HoftoCore(gains, np.array([0.5, 0.5, 0.0]), "eq17", cfg.substeps, "euler")
        _check_nonlinear(f"{where}.l1, l2, l3", gains, core, model, rate_hz)
    elif isinstance(cfg, HoftoConfig):
        gains = np.array(cfg.gains, dtype=float)
        powers = np.array(cfg.stage_powers(), dtype=float)
        core = HoftoCore(gains, powers, cfg.form, cfg.substeps, cfg.discretisation)
        _check_nonlinear(f"{where}.gains", gains, core, model, rate_hz)
    # dob and direct: stable at every rate (module notes)


def _joint(model: RobotModel, j: int) -> str:
    return f"joint {j + 1} ({model.joint_names[j]})"


def _check_momentum(where: str, cfg: MomentumConfig, model: RobotModel, rate: float) -> None:
    for j, k in enumerate(cfg.gain):
        if k / rate >= 2.0:
            raise ConfigError(
                f"{where}.gain[{j}] = {k:g} 1/s ({_joint(model, j)}) is unstable at {rate:g} Hz: "
                f"forward Euler needs gain/rate < 2, so gain < {2.0 * rate:g} 1/s"
            )


def eso_growth(k1: float, k2: float, k3: float, dt: float, substeps: int) -> tuple[float, float]:
    """(error growth per tick, largest stable bandwidth scale s or 0 if none) of the Euler ESO."""
    h = dt / substeps
    A, _ = error_matrices(k1, k2, k3)
    lam = np.linalg.eigvals(A)
    rho = float(np.max(np.abs(1.0 + h * lam))) ** substeps
    if np.any(lam.real >= 0.0):
        return rho, 0.0
    return rho, float(np.min(-2.0 * lam.real / (h * np.abs(lam) ** 2)))


def _check_eso(where: str, cfg: EsoConfig, model: RobotModel, rate: float) -> None:
    for j, (k1, k2, k3) in enumerate(zip(cfg.k1, cfg.k2, cfg.k3, strict=True)):
        rho, s_max = eso_growth(k1, k2, k3, 1.0 / rate, cfg.substeps)
        growth = rho**rate
        if growth <= GROWTH_LIMIT:
            continue
        if s_max == 0.0:
            hint = f"the error polynomial is not Hurwitz (needs k1·k2 > k3, got {k1 * k2:g})"
        else:
            hint = (
                f"scale (k1, k2, k3) by (s, s², s³) with s < {s_max:.3g} "
                f"or raise substeps above {cfg.substeps / s_max:.3g}"
            )
        raise ConfigError(
            f"{where}.k1, k2, k3[{j}] = ({k1:g}, {k2:g}, {k3:g}) ({_joint(model, j)}) are "
            f"unstable at {rate:g} Hz with {cfg.substeps} substep(s): the error grows "
            f"x{_fmt(growth)} per second (spectral radius {rho:.6g} per tick); {hint}"
        )


def _fmt(x: float) -> str:
    return f"{x:.3g}" if math.isfinite(x) else "inf"


def _check_nonlinear(
    where: str, gains: np.ndarray, core: HoftoCore, model: RobotModel, rate: float
) -> None:
    joints = gains.shape[1]
    zeros = np.zeros(joints)
    core.reset(zeros, zeros)
    for i, p in enumerate(PERTURBATION):
        core.z[i] = p
    dt = 1.0 / rate
    steps = min(max(int(round(SETTLE_TIME * rate)), 4), MAX_STEPS)
    worst = np.zeros(joints)
    with np.errstate(all="ignore"):
        for k in range(steps):
            core.step(zeros, zeros, dt)
            if k >= steps // 2:
                np.maximum(worst, np.abs(core.z[:3]).max(axis=0), out=worst)
            if not np.all(np.isfinite(core.z[:3])):
                worst[~np.all(np.isfinite(core.z[:3]), axis=0)] = np.inf
                break
    bad = np.nonzero(~(worst <= BOUND))[0]
    if bad.size:
        j = int(bad[0])
        values = ", ".join(f"{g:g}" for g in gains[:, j])
        raise ConfigError(
            f"{where}[{j}] = ({values}) ({_joint(model, j)}) are unstable at {rate:g} Hz: "
            f"on a unit double integrator a {PERTURBATION[2]:g} rad/s² error grows to "
            f"{_fmt(float(worst[j]))} (accepted: <= {BOUND:g}); lower the gains or raise "
            "substeps"
        )
