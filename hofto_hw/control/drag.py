"""Sensorless drag (hand guiding): the per-tick controller the loop calls in drag mode.

One :meth:`DragController.update` per tick takes the measured joint state, one observer's
tau_ext_hat, the enabling input and whether a fault is latched, and gives

- the reference ``q_cmd``, ``qd_cmd``, ``qdd_cmd`` (n,) for CSP (or CSV with ``qd_cmd``);
- ``reason`` (:class:`DragReason`), the stop request of this tick, and ``category`` (2 for a
  released enabling input, -1 otherwise: the caller's stop controller maps the force limit
  and an off-tool contact to its fault classes);
- ``tau_offset`` (n,) [N·m] to add to the drives' torque offset (``drag.hand_feedforward``:
  minus the tared estimate while dragging, so the position loop does not fight the hand and
  has no following error to take up when the hand lets go; zero otherwise);
- ``wrench`` (6,) [N, N·m] at the tool, ``contact_link`` (1-based, on an off-tool contact),
  ``mismatch`` [N·m], ``limited`` (bit mask of active walls/limits).

It never stops the arm itself: while not ACTIVE it feeds no force into the admittance (its
state decays with M_a/B_a) and reports; the loop's stop controller ramps to standstill. It
never allocates, formats, logs or blocks, except :meth:`ContactIsolation.isolate` in the one
tick an off-tool contact is first detected. Units SI.
"""

from __future__ import annotations

from enum import IntEnum

import numpy as np

from hofto_hw.config.drag import DragConfig
from hofto_hw.control.admittance import CartesianAdmittance, JointAdmittance
from hofto_hw.control.enabling import EnableEvent, Enabling
from hofto_hw.control.isolation import ContactIsolation
from hofto_hw.control.wrench import ToolJacobian, WrenchEstimator
from hofto_hw.model.robot import RobotModel


class DragReason(IntEnum):
    """The stop request of a tick (0 = none)."""

    NONE = 0
    ENABLE_RELEASED = 1  # category 2 (hold)
    FORCE_LIMIT = 2  # push above drag.force_limit
    CONTACT_OFF_TOOL = 3  # tau_ext_hat does not match a hand at the tool; see contact_link


class DragController:
    """See the module docstring. Build once (off the tick); :meth:`start` when the mode is
    entered; :meth:`update` every tick."""

    def __init__(
        self,
        cfg: DragConfig,
        model: RobotModel,
        gravity: tuple[float, float, float] = (0.0, 0.0, -9.81),
    ) -> None:
        n = model.n
        self.cfg = cfg
        self.n = n
        self.jac = ToolJacobian(model, cfg.tool_frame, cfg.singular_manipulability, cfg.dls_damping)
        self.estimator = WrenchEstimator(self.jac, cfg.payload.mass, cfg.payload.com, gravity)
        self.cartesian = cfg.space == "cartesian"
        self.admittance: CartesianAdmittance | JointAdmittance = (
            CartesianAdmittance(cfg, model, self.jac)
            if self.cartesian
            else JointAdmittance(cfg, model, self.jac)
        )
        self.isolation = ContactIsolation(
            model, self.jac, cfg.isolation_threshold, rotation=cfg.unlock.rotation
        )
        self.enabling = Enabling()
        # plain values for the tick (no pydantic there)
        self._standstill = float(cfg.standstill_speed)
        self._force_limit = float(cfg.force_limit)
        self._debounce = float(cfg.isolation_debounce)
        self._tare = bool(cfg.tare_on_enable)
        self._feedforward = bool(cfg.hand_feedforward)
        self.q_cmd = np.zeros(n)
        self.qd_cmd = np.zeros(n)
        self.qdd_cmd = np.zeros(n)
        self.wrench = self.estimator.wrench
        self.tau_bias = np.zeros(n)
        self.tau = np.zeros(n)  # tau_ext_hat minus the tare [N·m]
        self.tau_offset = np.zeros(n)  # add to the drives' torque offset [N·m]
        self.reason = 0
        self.category = -1
        self.contact_link = 0
        self.mismatch = 0.0
        self.limited = 0
        self.event = 0
        self._mismatch_time = 0.0
        self._zero6 = np.zeros(6)
        self._zero_n = np.zeros(n)
        self._qd_prev = np.zeros(n)
        self._abs = np.zeros(n)

    def start(self, q: np.ndarray) -> None:
        """Enter drag mode holding the measured position ``q`` (n,) [rad]."""
        np.copyto(self.q_cmd, q)
        self.qd_cmd.fill(0.0)
        self.qdd_cmd.fill(0.0)
        self.admittance.reset()
        self.enabling.reset()
        self.tau_bias.fill(0.0)
        self.reason = 0
        self.category = -1
        self.contact_link = 0
        self._mismatch_time = 0.0

    @property
    def active(self) -> bool:
        """True while the enabling input is held and the drag runs."""
        return self.enabling.state == 1

    def update(
        self,
        q: np.ndarray,
        qd: np.ndarray,
        tau_ext: np.ndarray,
        dt: float,
        pressed: bool,
        fault_latched: bool,
    ) -> int:
        """One tick (see module docstring); returns ``reason``."""
        np.abs(qd, out=self._abs)
        standstill = bool(self._abs.max() < self._standstill)
        ev = self.enabling.update(pressed, standstill, fault_latched)
        self.event = ev
        self.reason = 0
        self.category = -1
        if ev == EnableEvent.ENTERED:
            np.copyto(self.q_cmd, q)  # bumpless: start from where the arm is
            self.admittance.reset()
            if self._tare:
                np.copyto(self.tau_bias, tau_ext)
            self._mismatch_time = 0.0
            self.contact_link = 0
        elif ev == EnableEvent.RELEASED:
            self.reason = DragReason.ENABLE_RELEASED
            self.category = 2
        np.subtract(tau_ext, self.tau_bias, out=self.tau)
        jac = self.jac
        jac.update(self.q_cmd)
        self.estimator.update(self.tau)
        active = self.enabling.state == 1
        if active:
            if self.estimator.force_norm > self._force_limit:
                self.reason = DragReason.FORCE_LIMIT
            if self.isolation.check(self.tau):
                self._mismatch_time += dt
                if self._mismatch_time >= self._debounce:
                    if self.contact_link == 0:  # the one allocating call, once per contact
                        self.contact_link = self.isolation.isolate(q, self.tau)
                    self.reason = DragReason.CONTACT_OFF_TOOL
            else:
                self._mismatch_time = 0.0
            self.mismatch = self.isolation.mismatch
        # no force into the admittance unless dragging: its state then decays
        adm = self.admittance
        np.copyto(self._qd_prev, self.qd_cmd)
        if self.cartesian:
            qd_new = adm.update(self.wrench if active else self._zero6, self.q_cmd, dt)
        else:
            qd_new = adm.update(self.tau if active else self._zero_n, self.q_cmd, dt)
        self.limited = adm.shaping.limited
        if active and self._feedforward:
            np.negative(self.tau, out=self.tau_offset)
        else:
            self.tau_offset.fill(0.0)
        np.copyto(self.qd_cmd, qd_new)
        np.subtract(self.qd_cmd, self._qd_prev, out=self.qdd_cmd)
        self.qdd_cmd *= 1.0 / dt
        self._abs[:] = self.qd_cmd
        self._abs *= dt
        self.q_cmd += self._abs
        return self.reason
