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
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hofto_hw.config.models import FrictionConfig


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

    def update_held(self, qd: np.ndarray, state: np.ndarray, scratch: np.ndarray) -> np.ndarray:
        """Advance the held sign ``state`` (n,) in place: h_j = sign(qd_j) where |qd_j| > v_h,
        unchanged inside the band. ``scratch`` (2, n) float; allocation-free."""
        t, u = scratch[0], scratch[1]
        np.abs(qd, out=t)
        np.subtract(t, self.held_velocity, out=t)
        np.heaviside(t, 0.0, out=t)  # 1 outside the band, 0 inside
        np.sign(qd, out=u)
        np.subtract(u, state, out=u)
        np.multiply(u, t, out=u)
        np.add(state, u, out=state)
        return state

    def torque(
        self,
        qd: np.ndarray,
        out: np.ndarray,
        scratch: np.ndarray | None = None,
        state: np.ndarray | None = None,
    ) -> np.ndarray:
        """Friction torque [N·m] for joint velocity ``qd`` [rad/s], written into ``out`` (n,).

        ``scratch`` (3, n) is the caller's workspace (a ModelData owns one); allocation-free
        when given. ``state`` (n,): the held sign of the held-friction term, advanced in place
        (see :meth:`update_held`); None = no memory (the sign of this sample outside the band,
        0 inside). The parameters themselves are constant: two callers never share a buffer.
        """
        if scratch is None or scratch.shape[0] < 3:
            scratch = np.zeros((3, qd.shape[0]))
        s = scratch[0]
        if self.smooth_velocity > 0.0:
            np.divide(qd, self.smooth_velocity, out=s)
            np.tanh(s, out=s)
        else:
            np.sign(qd, out=s)
        np.multiply(self.coulomb, s, out=out)
        if self._stribeck_gap is not None:
            t = scratch[1]
            np.divide(qd, self.stribeck_velocity, out=t)
            np.square(t, out=t)
            np.negative(t, out=t)
            np.exp(t, out=t)
            np.multiply(t, s, out=t)
            np.multiply(t, self._stribeck_gap, out=t)
            np.add(out, t, out=out)
        np.multiply(self.viscous, qd, out=s)
        np.add(out, s, out=out)
        np.add(out, self.bias, out=out)
        if self.quadratic is not None:
            np.abs(qd, out=s)
            np.multiply(s, qd, out=s)
            np.multiply(s, self.quadratic, out=s)
            np.add(out, s, out=out)
        if self.held is not None:
            h = scratch[2]
            if state is None:
                h.fill(0.0)
                state = h
            self.update_held(qd, state, scratch[:2])
            t = scratch[0]
            np.divide(qd, self.held_velocity, out=t)
            np.square(t, out=t)
            np.negative(t, out=t)
            np.exp(t, out=t)
            np.multiply(t, state, out=t)
            if self.held_passive:  # zero while moving against the held sign (qd·h < 0)
                u = scratch[1]
                np.multiply(qd, state, out=u)
                np.heaviside(u, 1.0, out=u)
                np.multiply(t, u, out=t)
            np.multiply(t, self.held, out=t)
            np.add(out, t, out=out)
        return out
