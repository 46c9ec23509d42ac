"""The numpy references of the dynamics snapshot and the feed-forward, for the agreement tests
only: pinocchio's Python API for every algorithm (ABA, CRBA, Coriolis matrix, gravity,
nonlinear effects, RNEA), FrictionParams.torque for eq. (12) with its held memory, numpy for
Cᵀ·qd, tau - f and the finiteness check. The product's one implementation is
hofto_hw/model/snapshot.py and data.py over the kernels of hofto_hw/model/kernels.py (and the
native library)."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

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
            fr.torque(qd, self.f, self._scratch, self.data.friction_state)
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
    """ModelData.inverse_dynamics as pinocchio's RNEA + FrictionParams.torque (own memory)."""

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
        tau += m.friction.torque(qd, self._f, self._scratch, self.friction_state)
        return tau
