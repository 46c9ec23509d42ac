"""The numpy references of the dynamics snapshot and the feed-forward, for the agreement tests
only: pinocchio's Python API for every algorithm (ABA, CRBA, Coriolis matrix, gravity,
nonlinear effects, RNEA), :func:`friction_torque` (numpy) for eq. (12) with its held memory,
numpy for Cᵀ·qd, tau - f and the finiteness check. The product's one implementation is
hofto_hw/model/snapshot.py and data.py over the kernels of hofto_hw/model/kernels.py (and the
native library)."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from hofto_hw.model.friction import FrictionParams
from hofto_hw.model.snapshot import Needs


class ReferenceSnapshot:
    """DynamicsSnapshot's terms and ``compute`` (same attribute names), as numpy calls."""

    backend = "reference"
    native = False

    def __init__(self, model, needs: Needs | int) -> None:  # type: ignore[no-untyped-def]
        needs = Needs(needs)
        if needs & Needs.ACCEL:
            needs |= Needs.FRICTION
        self.model, self.needs, n = model, needs, model.n
        self.data = model.create_data()  # friction_state, reset_friction_state
        self.data.friction_state = np.zeros(n)
        self.pm, self.pd = model.pin_model, model.pin_model.createData()
        self.M, self.C = np.zeros((n, n)), np.zeros((n, n))
        self.g, self.nle, self.accel = np.zeros(n), np.zeros(n), np.zeros(n)
        self.ct_qd, self.f, self.total = np.zeros(n), np.zeros(n), np.zeros(n)
        self._scratch = np.zeros((3, n))
        self.finite = True

    def reset_memory(self) -> None:
        self.data.friction_state.fill(0.0)

    def compute(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> bool:
        self.finite = math.isfinite(np.sum(q) + np.sum(qd) + np.sum(tau))
        if not self.finite:
            return False
        pm, pd, needs = self.pm, self.pd, self.needs
        if needs & Needs.FRICTION:
            fr = self.model.friction
            friction_torque(fr, qd, self.f, self._scratch, self.data.friction_state)
            np.subtract(tau, self.f, out=self.total)
        if needs & Needs.ACCEL:
            np.copyto(self.accel, pin.aba(pm, pd, q, qd, self.total))
        if needs & Needs.MASS:
            np.copyto(self.M, pin.crba(pm, pd, q))
        if needs & Needs.CORIOLIS_T:
            np.copyto(self.C, pin.computeCoriolisMatrix(pm, pd, q, qd))
            np.dot(self.C.T, qd, out=self.ct_qd)
        if needs & Needs.GRAVITY:
            np.copyto(self.g, pin.computeGeneralizedGravity(pm, pd, q))
        if needs & Needs.NLE:
            np.copyto(self.nle, pin.nonLinearEffects(pm, pd, q, qd))
        return True


class ReferenceData:
    """ModelData.inverse_dynamics as pinocchio's RNEA + :func:`friction_torque` (own memory)."""

    def __init__(self, model) -> None:  # type: ignore[no-untyped-def]
        n = model.n
        self.model, self.pd = model, model.pin_model.createData()
        self.friction_state = np.zeros(n)
        self._f, self._scratch, self._tau = np.zeros(n), np.zeros((3, n)), np.zeros(n)

    def reset_friction_state(self) -> None:
        self.friction_state.fill(0.0)

    def inverse_dynamics(
        self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, out: np.ndarray | None = None
    ) -> np.ndarray:
        m = self.model
        tau = self._tau if out is None else out
        np.copyto(tau, pin.rnea(m.pin_model, self.pd, q, qd, qdd))
        tau += friction_torque(m.friction, qd, self._f, self._scratch, self.friction_state)
        return tau


def update_held(fr: FrictionParams, qd: np.ndarray, state: np.ndarray, scratch: np.ndarray) -> None:
    """The held sign ``state`` (n,) advanced in place: h_j = sign(qd_j) where |qd_j| > v_h,
    unchanged inside the band. ``scratch`` (2, n)."""
    t, u = scratch[0], scratch[1]
    np.abs(qd, out=t)
    np.subtract(t, fr.held_velocity, out=t)
    np.heaviside(t, 0.0, out=t)  # 1 outside the band, 0 inside
    np.sign(qd, out=u)
    np.subtract(u, state, out=u)
    np.multiply(u, t, out=u)
    np.add(state, u, out=state)


def friction_torque(
    fr: FrictionParams,
    qd: np.ndarray,
    out: np.ndarray,
    scratch: np.ndarray | None = None,
    state: np.ndarray | None = None,
) -> np.ndarray:
    """Eq. (12) as numpy calls (the product's FrictionParams.torque before the kernel became
    its one implementation): f(qd) [N·m] into ``out`` (n,), ``scratch`` (3, n), ``state`` the
    held sign advanced in place (None = no memory)."""
    if scratch is None or scratch.shape[0] < 3:
        scratch = np.zeros((3, qd.shape[0]))
    s = scratch[0]
    if fr.smooth_velocity > 0.0:
        np.divide(qd, fr.smooth_velocity, out=s)
        np.tanh(s, out=s)
    else:
        np.sign(qd, out=s)
    np.multiply(fr.coulomb, s, out=out)
    if fr.stribeck_static is not None:
        t = scratch[1]
        np.divide(qd, fr.stribeck_velocity, out=t)
        np.square(t, out=t)
        np.negative(t, out=t)
        np.exp(t, out=t)
        np.multiply(t, s, out=t)
        np.multiply(t, fr.stribeck_static - fr.coulomb, out=t)
        np.add(out, t, out=out)
    np.multiply(fr.viscous, qd, out=s)
    np.add(out, s, out=out)
    np.add(out, fr.bias, out=out)
    if fr.quadratic is not None:
        np.abs(qd, out=s)
        np.multiply(s, qd, out=s)
        np.multiply(s, fr.quadratic, out=s)
        np.add(out, s, out=out)
    if fr.held is not None:
        h = scratch[2]
        if state is None:
            h.fill(0.0)
            state = h
        update_held(fr, qd, state, scratch[:2])
        t = scratch[0]
        np.divide(qd, fr.held_velocity, out=t)
        np.square(t, out=t)
        np.negative(t, out=t)
        np.exp(t, out=t)
        np.multiply(t, state, out=t)
        if fr.held_passive:  # zero while moving against the held sign (qd·h < 0)
            u = scratch[1]
            np.multiply(qd, state, out=u)
            np.heaviside(u, 1.0, out=u)
            np.multiply(t, u, out=t)
        np.multiply(t, fr.held, out=t)
        np.add(out, t, out=out)
    return out
