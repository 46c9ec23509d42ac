"""Sensorless drag (hand guiding): the per-tick controller the loop calls in drag mode.

One :meth:`DragController.update` per tick takes the measured joint state, one observer's
tau_ext_hat, the enabling input and whether a fault is latched, and gives

- the reference ``q_cmd``, ``qd_cmd``, ``qdd_cmd`` (n,) for CSP (or CSV with ``qd_cmd``);
- ``reason`` (:class:`DragReason`), the stop request of this tick, and ``category`` (2 for a
  released enabling input, -1 otherwise: the caller's stop controller maps the force limit
  and an off-tool contact to its fault classes);
- ``tau_offset`` (n,) [N·m] to add to the drives' torque offset (``drag.hand_feedforward``:
  minus ``tau`` while dragging, so the position loop does not fight the hand and has no
  following error to take up when the hand lets go; zero otherwise);
- ``wrench`` (6,) [N, N·m] at the tool, ``contact_link`` (1-based, on an off-tool contact),
  ``mismatch`` [N·m], ``limited`` (bit mask of active walls/limits).

The observer's estimate is low-passed twice: ``force_filter_hz`` (5 Hz) for the admittance
and the feed-forward (``tau``: a hand pushes below a few Hz, a collision-tuned observer
chatters and rings with the admittance above), ``isolation_filter_hz`` (50 Hz) for the
off-tool check (``tau_iso``: a contact's onset must stay sharp). A release detector scales
``tau`` down while ``tau_iso`` falls below ``release_ratio`` of it (the hand letting go is
seen at the fast filter's speed), and a second one zeroes it when the arm falls behind a
steady command (``release_lag_ratio``: seen in the arm's motion, before a slow observer's
estimate falls). The tare is the mean of the raw estimate from the mode's start to the press
(``tare_time``). Before the estimate is used, the friction model's error learned from
contact-free motion (:meth:`learn`, control/friction_residual.py) is taken off it. The
admittance's tool speed cap is lowered by the measured arm's lead over the command, so the
limit holds on the arm. :meth:`monitor_input` gives the collision monitor each observer row
minus that row's own hand share.

It never stops the arm itself: while not ACTIVE it feeds no force into the admittance (its
state decays with M_a/B_a) and reports; the loop's stop controller ramps to standstill. It
never allocates, formats, logs or blocks, except :meth:`ContactIsolation.isolate` in the one
tick an off-tool contact is first detected. Units SI.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from enum import IntEnum

import numpy as np

from hofto_hw.config.drag import DragConfig
from hofto_hw.control.admittance import CartesianAdmittance, JointAdmittance
from hofto_hw.control.enabling import EnableEvent, Enabling
from hofto_hw.control.friction_residual import FrictionResidual
from hofto_hw.control.isolation import ContactIsolation
from hofto_hw.control.wrench import ToolJacobian, WrenchEstimator, norm3
from hofto_hw.jit import Backend
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
        backend: Backend = "python",
        hot: Mapping[str, np.ndarray] | None = None,
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
            model,
            self.jac,
            cfg.isolation_threshold,
            rotation=cfg.unlock.rotation,
            force_ratio=cfg.isolation_force_ratio,
            hold_time=cfg.isolation_hold_time,
        )
        self.enabling = Enabling()
        #: the friction model's error, learned from contact-free motion (None: off)
        self.friction = (
            FrictionResidual(
                model.friction,
                cfg.friction_learning_time,
                cfg.friction_learning_speed,
                limit=cfg.friction_learning_limit,
                backend=backend,
                hot=hot,
            )
            if cfg.friction_learning
            else None
        )
        self.friction_correction = np.zeros(n)  # taken off the estimate this tick [N·m]
        self._tau_in = np.zeros(n)
        self._tv = np.zeros(3)
        self._vc = np.zeros(3)
        self._vc_hist = np.zeros(20)
        self._vc_i = 0
        self._released = False  # the arm's motion says the hand let go
        self._fast_at = 0.0
        # its premise is the feed-forward (without it the drives fight the hand and the arm
        # lags any command it pushes): off without it
        self._lag_ratio = float(cfg.release_lag_ratio) if cfg.hand_feedforward else 0.0
        self._lag_min_speed = 0.02  # [m/s] below this a lag says nothing
        # plain values for the tick (no pydantic there)
        self._standstill = float(cfg.standstill_speed)
        self._force_limit = float(cfg.force_limit)
        self._debounce = float(cfg.isolation_debounce)
        self._tare = bool(cfg.tare_on_enable)
        self._feedforward = bool(cfg.hand_feedforward)
        self._filter_hz = float(cfg.force_filter_hz)
        self.q_cmd = np.zeros(n)
        self.qd_cmd = np.zeros(n)
        self.qdd_cmd = np.zeros(n)
        self.wrench = self.estimator.wrench
        self.tau_bias = np.zeros(n)
        self.tau = np.zeros(n)  # tau_ext_hat minus the tare, low-passed [N·m]
        self.tau_offset = np.zeros(n)  # add to the drives' torque offset [N·m]
        self.reason = 0
        self.category = -1
        self.contact_link = 0
        self.mismatch = 0.0
        self.limited = 0
        self.event = 0
        self._mismatch_time = 0.0
        self.profile = (1.0, 1.0, 1.0)  # the active safety profile's drag factors
        self._zero6 = np.zeros(6)
        self._zero_n = np.zeros(n)
        self._qd_prev = np.zeros(n)
        self._abs = np.zeros(n)
        self._raw = np.zeros(n)
        self._row = np.zeros(n)
        self._share = np.zeros(n)
        self._filt = np.zeros(n)  # the observer's estimate, low-passed [N·m]
        self._fiso = np.zeros(n)  # the same, low-passed for the isolation [N·m]
        self.tau_iso = np.zeros(n)  # _fiso minus the tare: what the isolation checks [N·m]
        self._iso_hz = float(cfg.isolation_filter_hz)
        self._release = float(cfg.release_ratio)
        self.release_scale = 1.0  # the slow estimate's scale by the release detector
        self._slow = np.zeros(n)  # the estimate low-passed over tare_time: the tare [N·m]
        self._filtering = False  # False: the next update starts the filters at their input
        self._tare_time = float(cfg.tare_time)
        self._tare_n = 0  # samples in the tare's mean so far

    def apply_profile(self, mass: float, damping: float, speed: float) -> None:
        """A safety profile's drag factors: virtual mass, damping and every speed limit of
        the admittance = the drag section's · ``mass``, ``damping``, ``speed`` (in place; off
        the drag mode: the loop switches profiles at standstill only)."""
        self.admittance.apply_profile(mass, damping, speed)
        self.profile = (mass, damping, speed)

    def start(self, q: np.ndarray) -> None:
        """Enter drag mode holding the measured position ``q`` (n,) [rad]."""
        np.copyto(self.q_cmd, q)
        self.qd_cmd.fill(0.0)
        self.qdd_cmd.fill(0.0)
        self.admittance.reset()
        self.enabling.reset()
        self.tau_bias.fill(0.0)
        self.tau.fill(0.0)
        if self.friction is not None:
            self.friction.solve()
        self._filtering = False
        self._tare_n = 0
        self._released = False
        self._vc_hist.fill(0.0)
        self.reason = 0
        self.category = -1
        self.contact_link = 0
        self._mismatch_time = 0.0

    def _lag_release(self, fast: float) -> None:
        """The release seen in the arm's motion (``release_lag_ratio``): with the hand
        feed-forward on, the drives cancel the estimated hand, so the arm keeps up with a
        steady command while the hand pushes as estimated; when the hand lets go, the
        feed-forward pulls the arm back and it falls behind a command that is not
        accelerating, within ~20 ms, long before a slow observer's estimate has fallen
        (paper HOFTO: its estimate falls ~110 N/s at the tool). Then ``_released`` zeroes
        the drag's force until the fast estimate rises 2 % above its lowest value since (a
        hand pushing again). The command's own acceleration is excluded, since the arm lags
        an accelerating command by the drives' tracking lag (0.19-0.85 of it at a push's
        onset). ``fast``: squared norm of ``tau_iso``; the measured tool velocity in ``_tv``
        (this tick's)."""
        vc3, tv = self._vc, self._tv
        np.matmul(self.jac.J[:3], self.qd_cmd, out=vc3)
        vc = norm3(vc3)
        hist = self._vc_hist
        prev = hist[self._vc_i]  # the command's speed 20 ms ago
        hist[self._vc_i] = vc
        self._vc_i = (self._vc_i + 1) % hist.shape[0]
        if self._released:
            if fast > self._fast_at * 1.02 or fast <= 0.0:
                self._released = False
            elif fast < self._fast_at:
                self._fast_at = fast
            return
        if vc < self._lag_min_speed or vc > prev + 0.002:
            return
        along = (tv[0] * vc3[0] + tv[1] * vc3[1] + tv[2] * vc3[2]) / vc
        if along < self._lag_ratio * vc:
            self._released = True
            self._fast_at = fast

    def _follow(self, state: np.ndarray, x: np.ndarray, gain: float) -> None:
        """One step of a first-order filter: state += (x - state)·gain, in place (n,)."""
        np.subtract(x, state, out=self._raw)
        self._raw *= gain
        state += self._raw

    def learn(self, qd: np.ndarray, tau_ext: np.ndarray, dt: float) -> None:
        """One tick of contact-free motion outside drag mode (the caller knows: no contact
        reported, no stop, not dragging): ``qd`` (n,) [rad/s], this controller's observer row
        ``tau_ext`` (n,) [N·m], ``dt`` [s]. Allocation-free."""
        if self.friction is not None:
            self.friction.learn(qd, tau_ext, dt)

    def monitor_input(self, tau_ext: np.ndarray, out: np.ndarray) -> np.ndarray:
        """The collision monitor's input while the hand drags: each observer's row of
        ``tau_ext`` (m, n) [N·m] minus the hand's share of *that row* (its own tool-force fit,
        tare off), into ``out`` (m, n). Per row, because the rows react to the hand at their
        own speed: the share of the drag's (filtered, or slower) estimate subtracted from a
        faster row leaves the hand's onset as a false collision. After :meth:`update` (the
        Jacobian at this tick's q_cmd); allocation-free."""
        share, row = self._share, self._row
        for i in range(tau_ext.shape[0]):
            np.subtract(tau_ext[i], self.tau_bias, out=row)
            self.isolation.tool_share(row, share)
            np.subtract(tau_ext[i], share, out=out[i])
        return out

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
        if self.friction is not None:  # the friction model's learned error off the estimate
            self.friction.correction(qd, self.friction_correction)
            np.subtract(tau_ext, self.friction_correction, out=self._tau_in)
            tau_ext = self._tau_in
        # the estimate low-passed (first order; alpha = 1: off), then the tare off
        on = self._filtering
        self._filtering = True
        self._follow(self._filt, tau_ext, _low_pass_gain(self._filter_hz, dt) if on else 1.0)
        self._follow(self._fiso, tau_ext, _low_pass_gain(self._iso_hz, dt) if on else 1.0)
        if self.enabling.state != 1:  # the tare filter runs until the press
            # the mean of the raw estimate since the mode began, then an exponential mean
            # over tare_time (a short wait before the press still averages every sample)
            self._tare_n += 1
            tt = self._tare_time
            beta = 1.0 - math.exp(-dt / tt) if tt > 0.0 else 1.0
            self._follow(self._slow, tau_ext, max(beta, 1.0 / self._tare_n))
        ev = self.enabling.update(pressed, standstill, fault_latched)
        self.event = ev
        self.reason = 0
        self.category = -1
        if ev == EnableEvent.ENTERED:
            # q_cmd goes on from the hold it commanded (bumpless for a CSP drive): a jump to
            # the measured q (the servo's following error, ~1 mrad while it settles after
            # an enable) is a velocity feed-forward of 1 rad/s in one cycle at the drive
            self.admittance.reset()
            if self._tare:
                np.copyto(self.tau_bias, self._slow)
            self._mismatch_time = 0.0
            self.contact_link = 0
            self.isolation.reset()
            self._released = False
            self._vc_hist.fill(0.0)
        elif ev == EnableEvent.RELEASED:
            self.reason = DragReason.ENABLE_RELEASED
            self.category = 2
        np.subtract(self._filt, self.tau_bias, out=self.tau)
        np.subtract(self._fiso, self.tau_bias, out=self.tau_iso)
        # release: the fast estimate falls before the slow one; follow it down (never up:
        # a new push still comes in through the slow, smooth path)
        self.release_scale = 1.0
        jac = self.jac
        jac.update(self.q_cmd)
        # the arm's measured tool velocity: the lag release and the admittance's speed cap
        tv = self._tv
        np.matmul(jac.J[:3], qd, out=tv)
        arm = norm3(tv)
        slow = float(np.dot(self.tau, self.tau))
        fast = float(np.dot(self.tau_iso, self.tau_iso))
        if self._release > 0.0 and slow > 0.0 and fast < self._release * self._release * slow:
            self.release_scale = math.sqrt(fast / slow) / self._release
        if self._lag_ratio > 0.0 and self.enabling.state == 1:
            self._lag_release(fast)
            if self._released:
                self.release_scale = 0.0
        if self.release_scale < 1.0:
            self.tau *= self.release_scale
        self.estimator.update(self.tau)
        active = self.enabling.state == 1
        if active:
            if self.estimator.force_norm > self._force_limit:
                self.reason = DragReason.FORCE_LIMIT
            if self.isolation.check(self.tau_iso, dt):
                self._mismatch_time += dt
                if self._mismatch_time >= self._debounce:
                    if self.contact_link == 0:  # the one allocating call, once per contact
                        self.contact_link = self.isolation.isolate(q, self.tau_iso)
                    self.reason = DragReason.CONTACT_OFF_TOOL
            else:
                self._mismatch_time = 0.0
            self.mismatch = self.isolation.mismatch
        # no force into the admittance unless dragging: its state then decays
        adm = self.admittance
        np.copyto(self._qd_prev, self.qd_cmd)
        # the arm's measured tool speed (arm): the limit holds on the arm, not only on the
        # command
        if self.cartesian:
            qd_new = adm.update(self.wrench if active else self._zero6, self.q_cmd, dt, arm)
        else:
            qd_new = adm.update(self.tau if active else self._zero_n, self.q_cmd, dt, arm)
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


def _low_pass_gain(hz: float, dt: float) -> float:
    """The gain of a first-order low-pass at ``hz`` [Hz] over ``dt`` [s], 1 - exp(-2π·hz·dt)
    (1: no filter, for hz <= 0)."""
    return 1.0 - math.exp(-2.0 * math.pi * hz * dt) if hz > 0.0 else 1.0
