"""External-torque observers: direct (eq. 2), ESO (eq. 5), DOB, momentum, STA, HOFTO (eq. 17).

Build one from its config with :func:`make_observer`; every observer has
``reset(q, qd)`` and ``update(q, qd, tau, dt) -> tau_ext_hat``.
"""

from __future__ import annotations

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
from hofto_hw.model.robot import RobotModel
from hofto_hw.observers.base import ModelTerms, Observer
from hofto_hw.observers.direct import DirectObserver
from hofto_hw.observers.dob import DobObserver
from hofto_hw.observers.eso import EsoCore, EsoObserver
from hofto_hw.observers.hofto import HoftoCore, HoftoObserver
from hofto_hw.observers.metrics import error_indices
from hofto_hw.observers.momentum import MomentumObserver
from hofto_hw.observers.sta import StaObserver

OBSERVER_TYPES = ("direct", "eso", "dob", "momentum", "sta", "hofto")


def make_observer(cfg: ObserverConfig, model: RobotModel) -> Observer:
    """The observer a validated config section describes, on ``model``."""
    if isinstance(cfg, HoftoConfig):
        return HoftoObserver(
            model,
            np.array(cfg.gains, dtype=float),
            np.array(cfg.stage_powers(), dtype=float),
            cfg.form,
            cfg.substeps,
            cfg.discretisation,
        )
    if isinstance(cfg, EsoConfig):
        return EsoObserver(model, cfg.k1, cfg.k2, cfg.k3, cfg.substeps)
    if isinstance(cfg, DobConfig):
        return DobObserver(model, cfg.cutoff, cfg.nominal_inertia)
    if isinstance(cfg, MomentumConfig):
        return MomentumObserver(model, cfg.gain)
    if isinstance(cfg, StaConfig):
        return StaObserver(model, cfg.l1, cfg.l2, cfg.l3, cfg.substeps)
    if isinstance(cfg, DirectConfig):
        return DirectObserver(model, cfg.accel_filter_hz)
    raise TypeError(f"unknown observer config {type(cfg).__name__}")


__all__ = [
    "OBSERVER_TYPES",
    "DirectObserver",
    "DobObserver",
    "EsoCore",
    "EsoObserver",
    "HoftoCore",
    "HoftoObserver",
    "ModelTerms",
    "MomentumObserver",
    "Observer",
    "StaObserver",
    "error_indices",
    "make_observer",
]
