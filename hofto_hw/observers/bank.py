"""ObserverBank: every observer of a tick updated by one compiled call, each estimate written
straight into its row of the caller's output.

A tick updates its observers (HOFTO and the momentum observer in the shipped configs) from
one :class:`~hofto_hw.model.snapshot.DynamicsSnapshot`. Done observer by observer, each
update is a Python call, a compiled call taking a dozen arrays (~0.2 µs each) and a copy into
the tick's row; inside a loop whose other work flushes the caches every one of those costs
several times more. The bank makes it one compiled call
(:func:`hofto_hw.observers.kernels.bank_update`) with four array arguments, running each
observer's own kernel arithmetic, so the estimates are the per-observer ones bit for bit.

What the bank fuses: HOFTO (any order, form, discretisation, substeps), momentum, ESO, STA
and DOB observers that run their compiled kernels (``backend == "numba"``). Any other
observer (direct, one whose kernel runs as Python, a subclass) is updated after the fused
ones through its own ``update_snapshot`` and copied into its row; without the compiled path
(``HOFTO_HW_NO_NUMBA=1``) that is every observer.

Ownership: the observers keep their state arrays (``reset``, replay and standalone
``update`` keep working on them); the bank passes those arrays themselves (``args``: a tuple
per kind of each observer's arrays, taken at construction) to the compiled call, which
updates them in place, step-size terms included (HOFTO's transition matrix for the current
step, DOB's discrete pole: the observers' own, recomputed when dt changes). Contract: the
observers' state and parameter arrays and the snapshot's term arrays (``M``, ``accel``,
``f``, ``g``, ``ct_qd``, ``nle``) are allocated once and updated in place; an owner that
rebinds one to a new array must build a new bank (:meth:`ObserverBank.bound` says whether
the bank still holds the arrays its owners hold).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from hofto_hw import jit
from hofto_hw.model.snapshot import DynamicsSnapshot
from hofto_hw.observers import kernels as K
from hofto_hw.observers.base import Observer
from hofto_hw.observers.dob import DobObserver
from hofto_hw.observers.eso import EsoObserver
from hofto_hw.observers.hofto import HoftoObserver
from hofto_hw.observers.momentum import MomentumObserver
from hofto_hw.observers.sta import StaObserver

#: the snapshot's term arrays the kernel reads, in the order of the table's row 0
_TERMS = ("M", "accel", "f", "g", "ct_qd", "nle")
#: the terms each fusable observer reads
_READS = {
    HoftoObserver: ("M", "accel"),
    EsoObserver: ("M", "accel"),
    StaObserver: ("M", "accel"),
    MomentumObserver: ("M", "f", "g", "ct_qd"),
    DobObserver: ("f", "nle"),
}


def _fit(arr: np.ndarray, shape: tuple[int, ...], symmetric: bool = False) -> bool:
    """A float64 array of ``shape`` the kernel can address as C-ordered (a symmetric matrix in
    either storage order: pinocchio's M is column-major, and its transpose is itself)."""
    return (
        isinstance(arr, np.ndarray)
        and arr.dtype == np.float64
        and arr.shape == shape
        and (arr.flags.c_contiguous or (symmetric and arr.flags.f_contiguous))
        and arr.flags.writeable
    )


def _fields_of(arrays: list[np.ndarray], record: np.ndarray) -> bool:
    """The observer's arrays are still fields of its record (what the compiled call reads):
    an owner that rebound one runs through its own update."""
    return all(np.shares_memory(a, record) for a in arrays)


class ObserverBank:
    """``observers`` updated from ``snapshot`` into the rows of ``out`` (k, n) float64, row i
    for observer i (``out`` is the caller's; at least one row per observer).

    :meth:`update` is the hot call; ``fused`` names the observers the compiled call updates,
    ``rest`` the ones updated one by one (all of them with ``fuse=False``: the per-observer
    reference). Allocation-free after construction."""

    def __init__(
        self,
        observers: Sequence[Observer],
        snapshot: DynamicsSnapshot,
        out: np.ndarray,
        fuse: bool = True,
    ) -> None:
        n = snapshot.n
        if not _fit(out, out.shape) or out.ndim != 2 or out.shape[1] != n:
            raise ValueError(f"out must be a writable C-contiguous float64 (k, {n}) array")
        if out.shape[0] < len(observers):
            raise ValueError(f"out has {out.shape[0]} rows for {len(observers)} observers")
        self.observers = list(observers)
        self.snapshot = snapshot
        self.out = out
        self._keep: list[tuple[object, str, np.ndarray]] = []  # (owner, attribute, array)
        self._rest: list[tuple[Observer, np.ndarray]] = []
        groups: list[list[tuple]] = [[] for _ in range(5)]  # per kind (kernels.BANK_*)
        fused: list[str] = []
        terms: list[np.ndarray] = []
        self._has: set[str] = set()
        for attr in _TERMS:
            shape = (n, n) if attr == "M" else (n,)
            arr = getattr(snapshot, attr, None)
            if _fit(arr, shape, symmetric=attr == "M"):  # M(q) is symmetric (the snapshot's)
                self._keep.append((snapshot, attr, arr))
                self._has.add(attr)
            else:
                arr = np.zeros(shape)  # not computed: no fused observer reads it
            terms.append(arr)
        self.terms = tuple(terms)
        for i, obs in enumerate(self.observers):
            entry = self._entry(obs, i, n) if fuse and jit.available() else None
            if entry is None:
                self._rest.append((obs, out[i]))
            else:
                groups[entry[0]].append(entry[1])
                fused.append(obs.name)
        #: the compiled call's observers: one tuple per kind, None for a kind with none
        self.args = tuple(tuple(g) if g else None for g in groups)
        self.fused = tuple(fused)
        self.rest = tuple(o.name for o, _ in self._rest)
        if fused and not jit.warm(self._warm):
            self.args = (None,) * 5
            self._rest = [(o, out[i]) for i, o in enumerate(self.observers)]
            self.fused, self.rest = (), tuple(o.name for o in self.observers)
        self._kernel = K.bank_update
        self._any = len(self.fused) > 0
        self._only = not self._rest

    # ------------------------------------------------------------------- the tick

    def update(self, dt: float) -> None:
        """Advance every observer by dt [s] with the snapshot's current sample and terms
        (``snapshot.compute`` done by the caller); each estimate lands in its row of ``out``
        (NaN rows for a non-finite sample or dt, the observers' states untouched)."""
        snap = self.snapshot
        if self._any:
            self._kernel(
                self.args, self.terms, self.out, snap.q, snap.qd, snap.tau, snap.finite, dt
            )
            if self._only:
                return
        for obs, row in self._rest:
            np.copyto(row, obs.update_snapshot(snap, dt))

    # ------------------------------------------------------------------ building

    def bound(self) -> bool:
        """The arrays the bank passes are still the ones their owners hold."""
        return all(getattr(o, a) is arr for o, a, arr in self._keep)

    def _arrays(
        self, pairs: Sequence[tuple[object, str, tuple[int, ...]]]
    ) -> list[np.ndarray] | None:
        """The ``owner.attr`` arrays of the given shapes, or None if one does not fit (that
        observer then runs through its own update)."""
        arrays = [(o, a, getattr(o, a), shape) for o, a, shape in pairs]
        if not all(_fit(arr, shape) for _, _, arr, shape in arrays):
            return None
        self._keep += [(o, a, arr) for o, a, arr, _ in arrays]
        return [arr for _, _, arr, _ in arrays]

    def _entry(self, obs: Observer, i: int, n: int) -> tuple[int, tuple] | None:
        """(kind, the observer's tuple) of a fusable observer (kernels.BANK_*), else None."""
        kind = type(obs)
        if kind not in _READS or getattr(obs, "backend", "python") != "numba" or obs.n != n:
            return None
        if obs.needs & ~self.snapshot.needs or not all(t in self._has for t in _READS[kind]):
            return None  # the snapshot does not compute (or hold) what this observer reads
        if kind is HoftoObserver:
            core = obs.core  # type: ignore[attr-defined]
            s = core.stages
            pairs = [(core, "z", (s, n)), (core, "_neg_gains", (s, n)), (core, "powers", (s,))]
            arrs = self._arrays([*pairs, (core, "prev", (n,))])
            if arrs is None or not _fields_of(arrs, core.record):
                return None
            return K.BANK_HOFTO, (i, core.record)
        if kind is MomentumObserver:
            arrs = self._arrays([(obs, a, (n,)) for a in ("gain", "p0", "integral", "r")])
            if arrs is None or not _fields_of(arrs, obs.record):  # type: ignore[attr-defined]
                return None
            return K.BANK_MOMENTUM, (i, obs.record)  # type: ignore[attr-defined]
        if kind is EsoObserver or kind is StaObserver:
            if kind is EsoObserver:
                core = obs.core  # type: ignore[attr-defined]
                pairs = [(core, "z", (3, n)), (core, "k", (3, n)), (core, "prev", (n,))]
                code = K.BANK_ESO
            else:
                core = obs
                pairs = [(obs, "z", (3, n)), (obs, "gains", (3, n)), (obs, "prev", (n,))]
                code = K.BANK_STA
            arrs = self._arrays(pairs)
            return None if arrs is None else (code, (i, *arrs, int(core.substeps)))  # type: ignore[attr-defined]
        if kind is DobObserver:
            pairs = [(obs, a, (n,)) for a in ("_gj", "cutoff", "w")]
            arrs = self._arrays([*pairs, (obs, "work", (2, n))])
            return None if arrs is None else (K.BANK_DOB, (i, *arrs))
        return None

    def _warm(self) -> None:
        """Compile the kernel for these observers with a non-finite sample: NaN into a scratch
        output, every state untouched."""
        z = np.zeros(self.snapshot.n)
        K.bank_update(self.args, self.terms, np.zeros_like(self.out), z, z, z, False, 1e-3)
