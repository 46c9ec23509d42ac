"""External-torque observers: direct (eq. 2), ESO (eq. 5), DOB, momentum, STA, HOFTO (eq. 17).

Build one from its config with :func:`make_observer` (the table is
:mod:`hofto_hw.observers.registry`); every observer has
``reset(q, qd)`` and ``update(q, qd, tau, dt) -> tau_ext_hat``.
"""

from __future__ import annotations

from hofto_hw.observers import kernels
from hofto_hw.observers.bank import ObserverBank
from hofto_hw.observers.base import Observer
from hofto_hw.observers.direct import DirectObserver
from hofto_hw.observers.dob import DobObserver
from hofto_hw.observers.eso import EsoCore, EsoObserver
from hofto_hw.observers.hofto import HoftoCore, HoftoObserver
from hofto_hw.observers.metrics import error_indices
from hofto_hw.observers.momentum import MomentumObserver
from hofto_hw.observers.registry import OBSERVER_TYPES, OBSERVERS, make_observer
from hofto_hw.observers.sta import StaObserver

__all__ = [
    "OBSERVERS",
    "OBSERVER_TYPES",
    "DirectObserver",
    "DobObserver",
    "EsoCore",
    "EsoObserver",
    "HoftoCore",
    "HoftoObserver",
    "MomentumObserver",
    "Observer",
    "ObserverBank",
    "StaObserver",
    "error_indices",
    "kernels",
    "make_observer",
]
