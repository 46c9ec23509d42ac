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
observer (direct, a numpy-path observer, a subclass) is updated after the fused ones through
its own ``update_snapshot`` and copied into its row; without numba (``HOFTO_HW_NO_NUMBA=1``)
that is every observer, exactly as before.

Ownership: the observers keep their state arrays (``reset``, replay and standalone
``update`` keep working on them); the bank reads and writes those arrays in place through
their addresses, taken at construction, and keeps a reference to each, so none is freed
while the bank lives. Its own are constant: the per-observer step-size terms (HOFTO's
transition matrix for the current step, DOB's discrete pole), recomputed when dt changes.
Contract: the observers' state and parameter arrays and the snapshot's term arrays (``M``,
``accel``, ``f``, ``g``, ``ct_qd``, ``nle``) are allocated once and updated in place; an
owner that rebinds one to a new array must build a new bank (:meth:`ObserverBank.bound`
says whether the bank still points at the arrays its owners hold).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

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
        rows: list[list[int]] = []
        self._rest: list[tuple[Observer, np.ndarray]] = []
        fused: list[str] = []
        common = [n, out.shape[0], self._address(None, "", out)]
        for attr in _TERMS:
            shape = (n, n) if attr == "M" else (n,)
            arr = getattr(snapshot, attr, None)
            ok = _fit(arr, shape, symmetric=attr == "M")  # M(q) is symmetric (the snapshot's)
            common.append(self._address(snapshot, attr, arr) if ok else 0)
        self._terms = dict(zip(_TERMS, common[3:], strict=True))
        for i, obs in enumerate(self.observers):
            row = self._row(obs, i, n) if fuse and K.available() else None
            if row is None:
                self._rest.append((obs, out[i]))
            else:
                rows.append(row)
                fused.append(obs.name)
        tab = np.zeros((1 + len(rows), K.BANK_COLS), dtype=np.int64)
        tab[0, : len(common)] = common
        for r, row in enumerate(rows, start=1):
            tab[r, : len(row)] = row
        self._tab = tab
        self.fused = tuple(fused)
        self.rest = tuple(o.name for o, _ in self._rest)
        if rows and not K.warm(self._warm):
            self._tab = tab[:1]
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
            self._kernel(self._tab, snap.q, snap.qd, snap.tau, snap.finite, dt)
            if self._only:
                return
        for obs, row in self._rest:
            np.copyto(row, obs.update_snapshot(snap, dt))

    # ------------------------------------------------------------------ building

    def bound(self) -> bool:
        """The arrays the bank addresses are still the ones their owners hold."""
        return all(getattr(o, a) is arr for o, a, arr in self._keep if o is not None)

    def _address(self, owner: object, attr: str, arr: np.ndarray) -> int:
        self._keep.append((owner, attr, arr))
        return int(arr.ctypes.data)

    def _own(self, arr: np.ndarray) -> int:
        return self._address(None, "", arr)

    def _addresses(self, pairs: Sequence[tuple[object, str, tuple[int, ...]]]) -> list[int] | None:
        """Addresses of ``owner.attr`` arrays of the given shapes, or None if one does not fit
        (that observer then runs through its own update)."""
        arrays = [(o, a, getattr(o, a), shape) for o, a, shape in pairs]
        if not all(_fit(arr, shape) for _, _, arr, shape in arrays):
            return None
        return [self._address(o, a, arr) for o, a, arr, _ in arrays]

    def _row(self, obs: Observer, i: int, n: int) -> list[int] | None:
        """The table row of a fusable observer (its kind, its output row, ...), else None."""
        kind = type(obs)
        if kind not in _READS or getattr(obs, "backend", "numpy") != "numba" or obs.n != n:
            return None
        if obs.needs & ~self.snapshot.needs or not all(self._terms[t] for t in _READS[kind]):
            return None  # the snapshot does not compute (or hold) what this observer reads
        if kind is HoftoObserver:
            core = obs.core  # type: ignore[attr-defined]
            s = core.stages
            addr = self._addresses(
                [
                    (core, "z", (s, n)),
                    (core._hold, "prev", (n,)),
                    (core, "_neg_gains", (s, n)),
                    (core, "powers", (s,)),
                ]
            )
            if addr is None:
                return None
            hs = np.array([-1.0, 0.0])  # [h, a_h2] of T (h < 0: none yet)
            own = [self._own(hs), self._own(np.eye(s)), self._own(np.zeros((2, s)))]
            flags = (K.BANK_RECURSIVE if core.form == "recursive" else 0) | (
                K.BANK_TAYLOR if core.discretisation == "taylor" else 0
            )
            return [K.BANK_HOFTO, i, s, core.substeps, flags, *addr, *own]
        if kind is MomentumObserver:
            addr = self._addresses([(obs, a, (n,)) for a in ("gain", "p0", "integral", "r")])
            return None if addr is None else [K.BANK_MOMENTUM, i, 0, 1, 0, *addr]
        if kind is EsoObserver or kind is StaObserver:
            if kind is EsoObserver:
                core = obs.core  # type: ignore[attr-defined]
                pairs = [(core, "z", (3, n)), (core, "k", (3, n)), (core._hold, "prev", (n,))]
                code = K.BANK_ESO
            else:
                core = obs
                pairs = [(obs, "z", (3, n)), (obs, "gains", (3, n)), (obs._hold, "prev", (n,))]  # type: ignore[attr-defined]
                code = K.BANK_STA
            addr = self._addresses(pairs)
            return None if addr is None else [code, i, 3, core.substeps, 0, *addr]  # type: ignore[attr-defined]
        if kind is DobObserver:
            addr = self._addresses([(obs, a, (n,)) for a in ("_gj", "cutoff", "w")])
            if addr is None:
                return None
            own = [self._own(np.array([-1.0])), self._own(np.zeros(n))]
            return [K.BANK_DOB, i, 0, 1, 0, *addr, *own]
        return None

    def _warm(self) -> None:
        """Compile the kernel with a table of no observers (every state untouched)."""
        scratch = np.zeros_like(self.out)
        tab = self._tab[:1].copy()
        tab[0, K.BANK_OUT] = scratch.ctypes.data
        z = np.zeros(self.snapshot.n)
        K.bank_update(tab, z, z, z, True, 1e-3)
        K.bank_update(tab, z, z, z, False, 1e-3)
