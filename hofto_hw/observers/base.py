"""What every observer shares: the interface and the model terms of eq. (3)-(4).

All observers estimate tau_ext in eq. (1), M(q)·qdd + C(q,qd)·qd + g(q) + f(qd) = tau + tau_ext,
from measured q [rad], qd [rad/s] and motor torque tau [N·m] (arrays of shape (n,)). They
never read the bus and never decide to stop: safety/ does.

``update`` returns a view of the observer's own output buffer (valid until the next update);
copy it to keep it. Updates allocate nothing.

In a control tick the model terms are computed once for all estimators: the tick fills a
:class:`~hofto_hw.model.snapshot.DynamicsSnapshot` with the union of the observers' ``needs``
and calls ``update_snapshot(snap, dt)`` on each. ``update(q, qd, tau, dt)`` (replay, demo)
fills the observer's own snapshot and does the same; both give identical results. The tick
does it for all its observers at once through :class:`~hofto_hw.observers.bank.ObserverBank`
(one compiled call, the same numbers).

Backends: every observer but ``direct`` runs its kernel of :mod:`hofto_hw.observers.kernels`,
the only implementation of its formula: ``backend="numba"`` runs it compiled, ``"python"``
runs the same source as Python (no compilation; ~10-100x slower, for tests and debugging;
the name is kept for the callers), ``"auto"`` numba when available (what the loop runs).
The numpy formulation of each observer is the reference in
tests/hofto_hw/observers/reference.py; both backends agree with it to 1e-12.

Non-finite samples: an update whose q, qd, tau or dt holds a NaN or inf returns NaN on every
joint (so the fault stays visible to safety/, which reports it) and leaves the observer's
state untouched, so the next finite sample continues from the last finite state. ``reset``
clears every state.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from hofto_hw.model.robot import RobotModel
from hofto_hw.model.snapshot import DynamicsSnapshot, Needs


class Observer(Protocol):
    """External-torque observer."""

    name: str
    n: int

    def reset(self, q: np.ndarray, qd: np.ndarray) -> None:
        """Start from the arm at (q, qd) with no external torque."""
        ...

    #: model terms read from the snapshot
    needs: Needs

    def update(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray, dt: float) -> np.ndarray:
        """Advance by dt [s] with the newest samples; return tau_ext_hat [N·m], shape (n,)."""
        ...

    def update_snapshot(self, snap: DynamicsSnapshot, dt: float) -> np.ndarray:
        """As :meth:`update`, with the sample and model terms of ``snap`` (computed for at
        least ``needs``)."""
        ...


class SnapshotUpdate:
    """``update(q, qd, tau, dt)`` through the observer's own snapshot, for observers that
    define ``needs`` and ``update_snapshot``; call :meth:`_own_snapshot` in ``__init__``."""

    needs: Needs
    snapshot: DynamicsSnapshot

    def _own_snapshot(self, model: RobotModel, backend: str = "python") -> None:
        self.snapshot = DynamicsSnapshot(model, self.needs, backend)

    def _own_backend(self, model: RobotModel, backend: str, kernel: Callable[..., Any]) -> None:
        """Resolve ``backend`` (``auto`` -> numba when available), build the own snapshot,
        compile + warm ``kernel`` through ``self._warm`` (a failed compilation runs the
        kernel's source as Python: ``self.backend`` says which runs) and keep the kernel to
        call as ``self._kernel``."""
        from hofto_hw import jit

        self.backend = jit.resolve(backend)  # type: ignore[arg-type]
        self._own_snapshot(model, self.backend)
        if self.backend == "numba" and not jit.warm(self._warm):  # type: ignore[attr-defined]
            self.backend = "python"
        self._kernel = jit.compiled_or_python(kernel, self.backend)

    def update(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray, dt: float) -> np.ndarray:
        """Advance by dt [s] with the newest samples; return tau_ext_hat [N·m], shape (n,)."""
        snap = self.snapshot
        snap.compute(q, qd, tau)
        return self.update_snapshot(snap, dt)  # type: ignore[attr-defined]


class SampleGuard:
    """Allocation-free check that a sample (q, qd, tau, dt) is finite, and the all-NaN output
    an observer returns for one that is not."""

    def __init__(self, n: int) -> None:
        self._nan = np.full(n, np.nan)

    def finite(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray, dt: float) -> bool:
        # one sum: NaN and ±inf propagate into it (a finite sum can only overflow for values
        # near 1e308, which are refused too); about 3x cheaper than np.isfinite per array
        return math.isfinite(_sum(q) + _sum(qd) + _sum(tau) + dt)

    def usable(self, snap: DynamicsSnapshot, dt: float) -> bool:
        """The snapshot's sample and dt are finite."""
        return snap.finite and math.isfinite(dt)

    def nan(self) -> np.ndarray:
        """NaN on every joint (refilled each call: the caller may have written into it)."""
        self._nan.fill(np.nan)
        return self._nan


_sum = np.add.reduce


def per_joint(values: list[float] | np.ndarray, n: int, what: str) -> np.ndarray:
    """Gains as a float array of shape (n,), with a clear error otherwise."""
    arr = np.asarray(values, dtype=float).reshape(-1)
    if arr.shape != (n,):
        raise ValueError(f"{what}: expected {n} per-joint values, got {arr.size}")
    if not np.all(np.isfinite(arr)) or np.any(arr <= 0):
        raise ValueError(f"{what}: gains must be finite and > 0, got {arr.tolist()}")
    return arr
