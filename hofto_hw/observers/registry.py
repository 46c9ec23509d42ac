"""The observer registry: one table, observer type name -> config class, builder and the
default settings for replaying ~100 Hz recordings.

Adding an observer = its module + its config class (in ``hofto_hw.config.models``, added to
the ``ObserverConfig`` union, with ``per_joint_fields()``) + one :data:`OBSERVERS` entry.
Config validation reads the per-joint fields from the config class; :func:`make_observer`,
``hofto-hw replay --observer``, ``thresholds``, ``config check`` and the demo read this table.

Replay defaults (gains identical on all joints, SI units as in the config models):

- momentum: K_O = 20 1/s (a 50 ms first-order response);
- dob: low-pass 20 rad/s;
- direct: velocity differentiated and low-passed at 5 Hz;
- eso: triple pole at -15 rad/s (bandwidth parameterisation: 3·w0, 3·w0², w0³), stable
  under explicit Euler at dt = 0.01 s (w0·dt = 0.15);
- sta: NOT tuned for 100 Hz (its sign() stage chatters at dt = 0.01 s and these gains
  track a push too slowly); it has no calibrated thresholds;
- hofto: order 2, Levant's recursive form with lambda = 5, 3, 1.5, 1.1 (the paper's) and a
  Lipschitz constant L = 100 rad/s⁴ per joint: L1..L4 = lambda_i·L^(1/(4-i+1)). The paper's
  L = 300-400 chatters on 100 Hz data.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hofto_hw.config.models import (
    DirectConfig,
    DobConfig,
    EsoConfig,
    HoftoConfig,
    MomentumConfig,
    ObserverConfig,
    StaConfig,
)
from hofto_hw.jit import Backend
from hofto_hw.model.robot import RobotModel
from hofto_hw.observers.base import Observer
from hofto_hw.observers.direct import DirectObserver
from hofto_hw.observers.dob import DobObserver
from hofto_hw.observers.eso import EsoObserver
from hofto_hw.observers.hofto import HoftoObserver
from hofto_hw.observers.momentum import MomentumObserver
from hofto_hw.observers.sta import StaObserver


@dataclass(frozen=True)
class ObserverEntry:
    """One observer type: its config class, how to build it, its ~100 Hz replay default."""

    config: type
    build: Callable[[ObserverConfig, RobotModel, Backend], Observer]
    replay_default: Callable[[int], ObserverConfig]  # n_joints -> config


def levant_gains(lipschitz: float, n_joints: int, lambdas: tuple[float, ...]) -> list[list[float]]:
    """Rows L_i = lambda_i·L^(1/(k-i+1)) (i = 1..k, k = len(lambdas)) of the recursive form."""
    k = len(lambdas)
    return [[lam * lipschitz ** (1.0 / (k - i))] * n_joints for i, lam in enumerate(lambdas)]


_W0 = 15.0  # ESO replay default: triple pole [rad/s]

#: type name -> entry; the order is the order of CLI choices and of replay benchmarks
OBSERVERS: dict[str, ObserverEntry] = {
    "hofto": ObserverEntry(
        HoftoConfig,
        lambda c, m, b: HoftoObserver(
            m,
            np.array(c.gains, dtype=float),
            np.array(c.stage_powers(), dtype=float),
            c.form,
            c.substeps,
            c.discretisation,
            backend=b,
        ),
        lambda n: HoftoConfig(
            order=2,
            form="recursive",
            powers=[0.75, 2.0 / 3.0, 0.5, 0.0],
            gains=levant_gains(100.0, n, (5.0, 3.0, 1.5, 1.1)),
        ),
    ),
    "momentum": ObserverEntry(
        MomentumConfig,
        lambda c, m, b: MomentumObserver(m, c.gain, backend=b),
        lambda n: MomentumConfig(gain=[20.0] * n),
    ),
    "eso": ObserverEntry(
        EsoConfig,
        lambda c, m, b: EsoObserver(m, c.k1, c.k2, c.k3, c.substeps, backend=b),
        lambda n: EsoConfig(k1=[3.0 * _W0] * n, k2=[3.0 * _W0**2] * n, k3=[_W0**3] * n),
    ),
    "dob": ObserverEntry(
        DobConfig,
        lambda c, m, b: DobObserver(m, c.cutoff, c.nominal_inertia, backend=b),
        lambda n: DobConfig(cutoff=[20.0] * n),
    ),
    "sta": ObserverEntry(
        StaConfig,
        lambda c, m, b: StaObserver(m, c.l1, c.l2, c.l3, c.substeps, backend=b),
        lambda n: StaConfig(l1=[20.0] * n, l2=[60.0] * n, l3=[20.0] * n),
    ),
    "direct": ObserverEntry(
        DirectConfig,
        lambda c, m, b: DirectObserver(m, c.accel_filter_hz),
        lambda n: DirectConfig(accel_filter_hz=5.0),
    ),
}

OBSERVER_TYPES = tuple(OBSERVERS)


def make_observer(cfg: ObserverConfig, model: RobotModel, *, backend: Backend = "auto") -> Observer:
    """The observer a validated config section describes, on ``model``.

    ``backend``: ``auto`` (compiled when available, as the loop runs), ``numba`` (compiled
    and warmed here, or RuntimeError) or ``python`` (the same kernels' source as Python; see
    :mod:`hofto_hw.jit`)."""
    entry = OBSERVERS.get(cfg.type)
    if entry is None or not isinstance(cfg, entry.config):
        raise TypeError(f"unknown observer config {type(cfg).__name__}")
    return entry.build(cfg, model, backend)


def replay_default(name: str, n_joints: int) -> ObserverConfig:
    """The default config of observer type ``name`` for ~100 Hz recordings (KeyError if
    unknown)."""
    return OBSERVERS[name].replay_default(n_joints)
