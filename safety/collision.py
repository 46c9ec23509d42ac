"""Collision detection on the estimated external torque (safety decides, it never reads the bus).

:class:`CollisionMonitor` compares |tau_ext_hat_j| with a per-joint threshold every tick:

    thr_j = base_j + kv_j·|qd_j| + ka_j·|a_j| + kr_j·r_j + ks_j·s_j

- ``a`` is the acceleration from differentiated velocity, first-order low-passed: model errors
  in inertia show up as a residual proportional to acceleration (acceleration steps);
- ``r`` is a velocity-reversal indicator in [0, 1]: exp(-(qd/v_rev)²) weighted by how recently
  the joint last moved faster than v_rev (decaying with ``moving_time``), held with a decay of
  ``reversal_time``. Friction changes sign at a reversal and no friction model follows that
  exactly, so the residual spikes there; a joint that stands still (r -> 0) keeps its
  sensitive resting threshold, so a push on a holding arm is still seen;
- ``s`` = exp(-(qd/v_s)²) is the standstill indicator (``standstill_margin`` ks,
  ``standstill_velocity`` v_s; off by default): a joint at rest keeps the friction of its last
  direction of motion, which a separate standstill term covers without raising the base, the
  threshold in motion.
A joint trips after staying above its threshold for ``debounce_time`` and releases after
staying below ``release_ratio``·threshold for ``release_time`` (hysteresis).

Non-finite inputs: a NaN or inf in ``qd`` or ``tau_ext`` is reported in the same update
(``nonfinite`` names the joints, ``fault_nonfinite`` is the fault) and never enters the
filters: a joint with a non-finite velocity keeps its last finite acceleration, moving and
reversal state and its threshold uses its last finite velocity, so detection on it goes on
with its torque; a joint with a non-finite torque keeps its debounce/hysteresis state and
cannot trip or release in that update, while the other joints are judged as usual. Once the
inputs are finite again the monitor works as before. The monitor only *reports*: latching a
fault and the stop category it commands belong to the stop controller (safety/stop.py).

``update`` allocates nothing: all arrays are preallocated and written with ``out=``.
"""

from __future__ import annotations

import math

import numpy as np

from hofto_hw.config.collision import CollisionConfig


def _per_joint(values: list[float] | None, n: int) -> np.ndarray:
    return np.zeros(n) if values is None else np.asarray(values, dtype=float)


class CollisionMonitor:
    """Per-joint thresholds with debounce, hysteresis, velocity/acceleration/reversal terms.

    Public state after :meth:`update` (views, valid until the next update):
    ``detected`` (bool), ``joints`` (n,) bool tripped joints, ``threshold`` (n,) [N·m] the
    effective thresholds, ``ratio`` (n,) |tau_ext_hat| / threshold (0 where tau_ext_hat is
    not finite), ``nonfinite`` (n,) bool joints whose qd or tau_ext_hat was NaN/inf in this
    update, ``fault_nonfinite`` (bool) any of them.
    """

    def __init__(self, cfg: CollisionConfig) -> None:
        n = len(cfg.base)
        self.cfg = cfg
        self.n = n
        self.base = np.asarray(cfg.base, dtype=float)
        self.kv = _per_joint(cfg.velocity_gain, n)
        self.ka = _per_joint(cfg.acceleration_gain, n)
        self.kr = _per_joint(cfg.reversal_margin, n)
        self.v_rev = cfg.reversal_velocity
        self.ks = _per_joint(cfg.standstill_margin, n)
        self.still = np.zeros(n)
        self._still_now = np.zeros(n)
        self.detected = False
        self.joints = np.zeros(n, dtype=bool)
        self.threshold = self.base.copy()
        self.ratio = np.zeros(n)
        self.accel = np.zeros(n)
        self.moving = np.zeros(n)
        self.reversal = np.zeros(n)
        self._qd_prev = np.zeros(n)
        self._above_time = np.zeros(n)
        self._below_time = np.zeros(n)
        self._tmp = np.zeros(n)
        self._mask = np.zeros(n, dtype=bool)
        self._mask2 = np.zeros(n, dtype=bool)
        self.nonfinite = np.zeros(n, dtype=bool)
        self.fault_nonfinite = False
        self._ok_qd = np.zeros(n, dtype=bool)
        self._bad_qd = np.zeros(n, dtype=bool)
        self._bad_tau = np.zeros(n, dtype=bool)
        self._qd = np.zeros(n)  # qd with non-finite entries replaced by the last finite ones
        self._saved = np.zeros((3, n))  # accel, moving, reversal before this update
        self._saved_time = np.zeros((2, n))  # above/below times before this update
        self._started = False
        # (t >= 0) would hold with zero time above: a tiny floor keeps "0 = trip at once"
        self._trip_after = max(cfg.debounce_time - 1e-9, 1e-12)
        self._release_after = max(cfg.release_time - 1e-9, 1e-12)

    def reset(self, qd: np.ndarray | None = None) -> None:
        """Forget all state; ``qd`` (n,) [rad/s] seeds the acceleration estimate."""
        self.detected = False
        self.joints[:] = False
        self.threshold[:] = self.base
        self.ratio[:] = 0.0
        self.accel[:] = 0.0
        self.moving[:] = 0.0
        self.reversal[:] = 0.0
        self.still[:] = 0.0
        self._above_time[:] = 0.0
        self._below_time[:] = 0.0
        self.nonfinite[:] = False
        self.fault_nonfinite = False
        if qd is not None and not np.all(np.isfinite(qd)):
            qd = None  # a non-finite seed is no seed
        if qd is None:
            self._started = False
        else:
            self._qd_prev[:] = qd
            self.moving[:] = np.abs(qd) > self.v_rev
            self._started = True

    def features(self, qd: np.ndarray, dt: float) -> None:
        """Advance the threshold features (accel, moving, reversal) by one tick of dt [s].

        Joints whose ``qd`` is not finite keep their previous state (see the module notes).
        """
        ok, bad = self._ok_qd, self._bad_qd
        np.isfinite(qd, out=ok)
        np.logical_not(ok, out=bad)
        if not self._started:
            self._qd_prev.fill(0.0)
            np.copyto(self._qd_prev, qd, where=ok)
            self._started = True
        qd_ok = self._qd
        np.copyto(qd_ok, qd)
        np.copyto(qd_ok, self._qd_prev, where=bad)
        saved = self._saved
        np.copyto(saved[0], self.accel)
        np.copyto(saved[1], self.moving)
        np.copyto(saved[2], self.reversal)
        self._advance(qd_ok, dt)
        np.copyto(self.accel, saved[0], where=bad)
        np.copyto(self.moving, saved[1], where=bad)
        np.copyto(self.reversal, saved[2], where=bad)

    def _advance(self, qd: np.ndarray, dt: float) -> None:
        tmp = self._tmp
        # low-passed acceleration: a += alpha·((qd - qd_prev)/dt - a)
        np.subtract(qd, self._qd_prev, out=tmp)
        tmp *= 1.0 / dt
        tmp -= self.accel
        tau_a = 1.0 / (2.0 * math.pi * self.cfg.accel_filter_hz)
        tmp *= dt / (tau_a + dt)
        self.accel += tmp
        self._qd_prev[:] = qd
        # moving indicator: 1 while |qd| > v_rev, then decaying with moving_time
        np.abs(qd, out=tmp)
        np.greater(tmp, self.v_rev, out=self._mask)
        self.moving *= math.exp(-dt / self.cfg.moving_time)
        np.maximum(self.moving, self._mask, out=self.moving)
        # reversal: max(exp(-(qd/v_rev)²)·moving, decayed previous value)
        np.multiply(qd, 1.0 / self.v_rev, out=tmp)
        np.square(tmp, out=tmp)
        np.negative(tmp, out=tmp)
        np.exp(tmp, out=tmp)
        tmp *= self.moving
        self.reversal *= math.exp(-dt / self.cfg.reversal_time)
        np.maximum(self.reversal, tmp, out=self.reversal)
        self._standstill(qd, dt)

    def _standstill(self, qd: np.ndarray, dt: float) -> None:
        """s = exp(-(qd/v_s)²): 1 at rest, ~0 in motion (non-finite qd never gets here); with
        ``standstill_time`` T > 0 it rises with time constant T after a stop (the stop
        transient is the reversal term's) and drops at once when the joint moves."""
        now = self._still_now
        np.multiply(qd, 1.0 / self.cfg.standstill_velocity, out=now)
        np.square(now, out=now)
        np.negative(now, out=now)
        np.exp(now, out=now)
        T = self.cfg.standstill_time
        if T <= 0.0:
            np.copyto(self.still, now)
            return
        tmp = self._tmp
        np.subtract(now, self.still, out=tmp)
        tmp *= 1.0 - math.exp(-dt / T)
        tmp += self.still
        np.minimum(now, tmp, out=self.still)

    def update(self, tau_ext: np.ndarray, qd: np.ndarray, dt: float) -> bool:
        """One tick: estimated external torque (n,) [N·m], velocity (n,) [rad/s], dt [s].

        Returns whether any joint is in collision (also in ``detected``; which joints in
        ``joints``).
        """
        self.features(qd, dt)
        qd = self._qd  # finite: the last finite velocity where qd is not
        bad_tau = self._bad_tau
        np.isfinite(tau_ext, out=bad_tau)
        np.logical_not(bad_tau, out=bad_tau)
        np.logical_or(self._bad_qd, bad_tau, out=self.nonfinite)
        self.fault_nonfinite = bool(self.nonfinite.any())
        thr, tmp = self.threshold, self._tmp
        # thr = base + kv·|qd| + ka·|a| + kr·r
        np.abs(qd, out=tmp)
        np.multiply(tmp, self.kv, out=thr)
        thr += self.base
        np.abs(self.accel, out=tmp)
        tmp *= self.ka
        thr += tmp
        np.multiply(self.reversal, self.kr, out=tmp)
        thr += tmp
        np.multiply(self.still, self.ks, out=tmp)
        thr += tmp
        np.abs(tau_ext, out=tmp)
        np.copyto(tmp, 0.0, where=bad_tau)
        np.divide(tmp, thr, out=self.ratio)
        np.copyto(self._saved_time[0], self._above_time)
        np.copyto(self._saved_time[1], self._below_time)
        above, below = self._mask, self._mask2
        # debounce: time spent above the threshold
        np.greater(self.ratio, 1.0, out=above)
        self._above_time += dt
        self._above_time *= above
        # hysteresis: time spent below release_ratio·threshold
        np.less(self.ratio, self.cfg.release_ratio, out=below)
        self._below_time += dt
        self._below_time *= below
        # a joint without a finite torque neither trips nor releases in this update
        np.copyto(self._above_time, self._saved_time[0], where=bad_tau)
        np.copyto(self._below_time, self._saved_time[1], where=bad_tau)
        # trip: above for debounce_time; release: below for release_time
        np.greater_equal(self._above_time, self._trip_after, out=above)
        np.logical_or(self.joints, above, out=self.joints)
        np.greater_equal(self._below_time, self._release_after, out=below)
        np.logical_not(below, out=below)
        np.logical_and(self.joints, below, out=self.joints)
        self.detected = bool(self.joints.any())
        return self.detected
