"""Joint friction, eq. (12) of the paper, with optional smooth sign and Stribeck term.

    f_j(qd) = Fc_j·s(qd_j) + Fv_j·qd_j + B_j + (Fs_j - Fc_j)·exp(-(qd_j / vs_j)²)·s(qd_j)

with s = sign, or s(v) = tanh(v / v_s) when ``smooth_velocity`` v_s > 0 (the hard sign turns
noise at standstill into a ±Fc square wave). All quantities per joint, joint side: Fc, Fs, B
[N·m], Fv [N·m·s/rad], vs, v_s [rad/s].

Optional terms, both linear in their parameters (identification stays least squares):

- **held friction** (friction with memory) ``Fh_j·h_j·exp(-(qd_j/v_h)²)``: h_j is the sign of
  the last velocity whose magnitude exceeded the band v_h (``held_velocity``), kept while the
  joint is (nearly) still. A real joint at rest keeps the friction torque of its last
  direction of motion (the UR10e's joint 5 sits at -2.5 N·m for seconds while creeping at
  -3e-4 rad/s); sign(qd) or tanh(qd/v_s) predicts 0 or a random sign there. h is *state*: it
  lives in the caller's workspace (``ModelData``), never in these constant parameters, and
  its update is idempotent for a repeated qd (several calls per tick are harmless).
  ``held_passive`` (the simulated plant's setting) zeroes the term while the joint moves
  against the held sign, so that it can only resist motion: as an estimate of the motor torque
  (identification, observers) the two-sided form fits the real arm, but as a force in a
  simulation the two-sided form pushes a joint that creeps backwards inside the band and
  makes a PD-held arm limit-cycle at about v_h;
- **quadratic** ``Fq_j·qd_j·|qd_j|`` [N·m·s²/rad²].

The formula itself is written once, in :mod:`hofto_hw.model.kernels`: each term's feature
(the partial derivative of f_j with respect to its parameter) is one small function there, the
kernel ``friction_joint`` sums them times the parameters (the tick's snapshot and feed-forward
call it compiled) and ``friction_features`` returns them (:meth:`FrictionParams.features`:
identification's regressor columns); :meth:`FrictionParams.torque` runs
that kernel in a workspace the caller owns (:meth:`FrictionParams.workspace`, packed with the
parameters: the parameters stay constant, as pinocchio's Model, the workspace is the Data).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from hofto_hw.config.models import FrictionConfig

#: the linear parameters of eq. (12) in the order of :meth:`FrictionParams.features`' last
#: axis (:func:`hofto_hw.model.kernels.friction_features`); ``stribeck_gap`` is Fs - Fc
FEATURES = ("coulomb", "stribeck_gap", "viscous", "bias", "quadratic", "held")


@dataclass
class FrictionParams:
    """Per-joint friction coefficients, arrays of shape (n,)."""

    coulomb: np.ndarray
    viscous: np.ndarray
    bias: np.ndarray
    stribeck_static: np.ndarray | None = None
    stribeck_velocity: np.ndarray | None = None
    smooth_velocity: float = 0.0
    held: np.ndarray | None = None
    held_velocity: float = 0.005
    quadratic: np.ndarray | None = None
    held_passive: bool = False
    _stribeck_gap: np.ndarray | None = field(init=False, repr=False)

    def __post_init__(self) -> None:
        n = self.coulomb.shape[0]
        for name in (
            "coulomb",
            "viscous",
            "bias",
            "stribeck_static",
            "stribeck_velocity",
            "held",
            "quadratic",
        ):
            value = getattr(self, name)
            if value is not None:
                arr = np.array(value, dtype=float).reshape(-1)
                if arr.shape != (n,):
                    raise ValueError(f"friction.{name} has {arr.size} entries, expected {n}")
                setattr(self, name, arr)
        if (self.stribeck_static is None) != (self.stribeck_velocity is None):
            raise ValueError("give both stribeck_static and stribeck_velocity, or neither")
        if not self.held_velocity > 0.0:
            raise ValueError(f"friction.held_velocity must be > 0 rad/s, got {self.held_velocity}")
        self._stribeck_gap = (
            None if self.stribeck_static is None else self.stribeck_static - self.coulomb
        )

    @classmethod
    def zeros(cls, n: int) -> FrictionParams:
        """No friction on ``n`` joints."""
        return cls(np.zeros(n), np.zeros(n), np.zeros(n))

    @classmethod
    def structure(
        cls,
        n: int,
        smooth_velocity: float = 0.0,
        stribeck_velocity: np.ndarray | None = None,
        held_velocity: float | None = None,
        quadratic: bool = False,
        held_passive: bool = False,
    ) -> FrictionParams:
        """Every coefficient 0 on ``n`` joints, with the terms asked for (Stribeck with
        velocities vs (n,) [rad/s], held with band ``held_velocity`` v_h [rad/s], quadratic):
        the model a fit's :meth:`features` come from."""
        z = np.zeros(n)
        return cls(
            z,
            z,
            z,
            stribeck_static=None if stribeck_velocity is None else z,
            stribeck_velocity=stribeck_velocity,
            smooth_velocity=smooth_velocity,
            held=None if held_velocity is None else z,
            held_velocity=0.005 if held_velocity is None else held_velocity,
            quadratic=z if quadratic else None,
            held_passive=held_passive,
        )

    @classmethod
    def from_config(cls, cfg: FrictionConfig | None, n: int) -> FrictionParams:
        """Build from the YAML section (None = frictionless)."""
        if cfg is None:
            return cls.zeros(n)
        return cls(
            coulomb=np.array(cfg.coulomb, dtype=float),
            viscous=np.array(cfg.viscous, dtype=float),
            bias=np.zeros(n) if cfg.bias is None else np.array(cfg.bias, dtype=float),
            stribeck_static=None
            if cfg.stribeck_static is None
            else np.array(cfg.stribeck_static, dtype=float),
            stribeck_velocity=None
            if cfg.stribeck_velocity is None
            else np.array(cfg.stribeck_velocity, dtype=float),
            smooth_velocity=cfg.smooth_velocity,
            held=None if cfg.held is None else np.array(cfg.held, dtype=float),
            held_velocity=cfg.held_velocity,
            quadratic=None if cfg.quadratic is None else np.array(cfg.quadratic, dtype=float),
        )

    def copy(self) -> FrictionParams:
        return FrictionParams(
            self.coulomb.copy(),
            self.viscous.copy(),
            self.bias.copy(),
            None if self.stribeck_static is None else self.stribeck_static.copy(),
            None if self.stribeck_velocity is None else self.stribeck_velocity.copy(),
            self.smooth_velocity,
            None if self.held is None else self.held.copy(),
            self.held_velocity,
            None if self.quadratic is None else self.quadratic.copy(),
            self.held_passive,
        )

    def workspace(self) -> np.ndarray:
        """A workspace for :meth:`torque`: (ROWS, n) float64 with these parameters packed in
        (:func:`hofto_hw.model.kernels.pack_friction`). The caller owns it (one per caller,
        as pinocchio's Data to its Model); a workspace belongs to the parameters that made it:
        new parameters (a new FrictionParams) need a new workspace or a repack."""
        from hofto_hw.model import kernels as mk

        W = mk.workspace(self.coulomb.shape[0])
        mk.pack_friction(self, W)
        return W

    def torque(
        self,
        qd: np.ndarray,
        out: np.ndarray,
        scratch: np.ndarray | None = None,
        state: np.ndarray | None = None,
    ) -> np.ndarray:
        """Friction torque [N·m] for joint velocity ``qd`` [rad/s], written into ``out`` (n,).

        ``scratch`` is the caller's workspace from :meth:`workspace` (a ModelData owns one);
        allocation-free when given (None: a new one is made for this call). ``state`` (n,):
        the held sign of the held-friction term, advanced in place: h_j = sign(qd_j) where
        |qd_j| > v_h, unchanged inside the band; None = no memory (the sign of this sample
        outside the band, 0 inside). The parameters themselves are constant: two callers
        never share a buffer.

        The arithmetic is the one kernel :func:`hofto_hw.model.kernels.friction` (compiled
        where numba works, else its source run by the interpreter), the same the tick runs;
        the numpy formula is the agreement tests' reference (tests/hofto_hw/model/
        reference.py)."""
        kernel, F, STATE, ROWS = _kernel()
        if scratch is None:
            scratch = self.workspace()
        elif scratch.shape != (ROWS, self.coulomb.shape[0]):
            raise ValueError(
                f"friction workspace has shape {scratch.shape}, expected "
                f"{(ROWS, self.coulomb.shape[0])}: make it with FrictionParams.workspace()"
            )
        h = scratch[STATE]
        if state is None:
            h.fill(0.0)
        else:
            np.copyto(h, state)
        kernel(qd, scratch)
        np.copyto(out, scratch[F])
        if state is not None:
            np.copyto(state, h)
        return out

    def held_signs(self, qd: np.ndarray, initial: np.ndarray | None = None) -> np.ndarray:
        """The held sign (N, n) after each sample of velocities ``qd`` (N, n) [rad/s] in time
        order, from ``initial`` (n,) (default 0): the held-friction memory of :meth:`torque`
        (band ``held_velocity``) run over a whole recording, as identification needs it."""
        qd = self._samples(qd)
        h = np.zeros(qd.shape[1]) if initial is None else np.array(initial, dtype=float)
        out = np.empty_like(qd)
        _batch()[0](qd, self.held_velocity, h, out)
        return out

    def features(self, qd: np.ndarray, held: np.ndarray | None = None) -> np.ndarray:
        """The features of eq. (12) over N samples, (N, n, 6): per sample and joint the partial
        derivatives of the friction torque with respect to Fc, Fs - Fc, Fv, B, Fq, Fh
        (:data:`FEATURES`; 0 for a term these parameters do not have): the torque is their
        product with the parameters. ``qd`` (N, n) [rad/s]; ``held`` (N, n) the held sign at
        each sample (default :meth:`held_signs` of ``qd`` from 0). Only the structure counts
        (v_s, vs, v_h, which terms, passive), not the values: identification's regressor
        columns. The kernel is :func:`hofto_hw.model.kernels.friction_features`, the one
        :meth:`torque` sums."""
        qd = self._samples(qd)
        held = self.held_signs(qd) if held is None else np.ascontiguousarray(held, dtype=float)
        if held.shape != qd.shape:
            raise ValueError(f"friction features: held has shape {held.shape}, qd {qd.shape}")
        out = np.empty((*qd.shape, len(FEATURES)))
        _batch()[1](qd, held, self.workspace(), out)
        return out

    def _samples(self, qd: np.ndarray) -> np.ndarray:
        qd = np.ascontiguousarray(qd, dtype=float)
        if qd.ndim != 2 or qd.shape[1] != self.coulomb.shape[0]:
            raise ValueError(
                f"friction: velocities must have shape (N, {self.coulomb.shape[0]}), got {qd.shape}"
            )
        return qd


_Kernel = tuple[Callable[[np.ndarray, np.ndarray], None], int, int, int]
_KERNEL: list[_Kernel] = []


def _kernel() -> _Kernel:
    """The friction kernel (compiled and warmed on first use where numba works, else its
    source as Python) and its workspace's rows F, STATE and ROWS. Imported on first use:
    hofto_hw.model.kernels imports this module's package."""
    if not _KERNEL:
        from hofto_hw import jit
        from hofto_hw.model import kernels as mk

        z, W = np.zeros(1), mk.workspace(1)
        backend = jit.ready("auto", lambda: mk.friction(z, W))
        fn = jit.compiled_or_python(mk.friction, backend)
        _KERNEL.append((fn, mk.F, mk.STATE, mk.ROWS))
    return _KERNEL[0]


_BATCH: list[tuple[Callable[..., None], Callable[..., None]]] = []


def _batch() -> tuple[Callable[..., None], Callable[..., None]]:
    """The recording-wide kernels (held_series, feature_matrix), compiled and warmed on first
    use where numba works, else their source as Python (as :func:`_kernel`)."""
    if not _BATCH:
        from hofto_hw import jit
        from hofto_hw.model import kernels as mk

        z, W = np.zeros((1, 1)), mk.workspace(1)
        out = np.zeros((1, 1, mk.N_FEATURES))

        def warm() -> None:
            mk.held_series(z, 1.0, np.zeros(1), z.copy())
            mk.feature_matrix(z, z, W, out)

        backend = jit.ready("auto", warm)
        _BATCH.append(
            (
                jit.compiled_or_python(mk.held_series, backend),
                jit.compiled_or_python(mk.feature_matrix, backend),
            )
        )
    return _BATCH[0]
