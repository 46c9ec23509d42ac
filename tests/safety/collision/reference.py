"""The numpy reference of one collision-monitor tick, for the agreement tests only (the
product's one implementation is safety/collision/kernel.py; test_kernel.py checks that it
agrees with this one, compiled and as Python source). Allocation-free: every array is
preallocated and written with ``out=``.

:class:`ReferenceLevels` is a monitor driven by it, with the state layout and the ``step``
of :class:`safety.collision.CollisionLevels`."""

from __future__ import annotations

import math

import numpy as np

from safety.collision.params import (
    LOGICS,
    S_ACCEL_LEVEL,
    S_LOGIC,
    S_MOVING_TIME,
    S_PHASE_HOLD,
    S_RELEASE_AFTER,
    S_RELEASE_RATIO,
    S_REVERSAL_TIME,
    S_STILL_TIME,
    S_TAU_A,
    S_TRIP_AFTER,
    S_V_REV,
    S_V_STILL,
    MonitorParams,
)
from safety.collision.state import (
    F_ACCEL,
    F_MOVING,
    F_QD_OK,
    F_QD_PREV,
    F_REVERSAL,
    F_STILL,
    L_ABOVE,
    L_BELOW,
    L_RATIO,
    L_THR,
    ST_ACCEL_PHASE,
    ST_PHASE_LEFT,
    ST_STARTED,
    MonitorState,
)


class NumpyStep:
    """One tick of the monitor in numpy on ``state`` (see safety/collision/state.py)."""

    def __init__(self, p: MonitorParams, s: MonitorState) -> None:
        L, _, k, n = p.par.shape
        self.p, self.s = p, s
        self.k, self.L = k, L
        sc = p.scal
        self.v_rev = float(sc[S_V_REV])
        self.tau_a = float(sc[S_TAU_A])
        self.moving_time = float(sc[S_MOVING_TIME])
        self.reversal_time = float(sc[S_REVERSAL_TIME])
        self.v_still = float(sc[S_V_STILL])
        self.still_time = float(sc[S_STILL_TIME])
        self.accel_level = float(sc[S_ACCEL_LEVEL])
        self.phase_hold = float(sc[S_PHASE_HOLD])
        self.trip_after = float(sc[S_TRIP_AFTER])
        self.release_after = float(sc[S_RELEASE_AFTER])
        self.release_ratio = float(sc[S_RELEASE_RATIO])
        self.logic = LOGICS[int(sc[S_LOGIC])]
        self.phased = self.accel_level != math.inf  # thresholds-file monitors have one phase
        self.dec = [r for r in range(k) if p.deciding[r]]
        f = s.feat
        self.qd_prev, self.accel, self.moving = f[F_QD_PREV], f[F_ACCEL], f[F_MOVING]
        self.reversal, self.still, self.qd_ok = f[F_REVERSAL], f[F_STILL], f[F_QD_OK]
        self.base = (p.par[:, 0], p.par[:, 1])  # (L, k, n) per phase
        self.kv, self.ka, self.kr, self.ks = (p.par[:, i] for i in range(2, 6))
        self.thr = s.lev[:, L_THR, :k]
        self.ratio_rows = s.lev[:, L_RATIO, :k]
        self.ratio = s.lev[:, L_RATIO]
        self.fused = s.lev[:, L_RATIO, k]
        self.row_ratio = [s.lev[:, L_RATIO, r] for r in range(k)]
        self.above, self.below = s.lev[:, L_ABOVE], s.lev[:, L_BELOW]
        self.bad_tau, self.bad_fused = s.bad[:k], s.bad[k]
        self.bad_rows = s.bad[: k + 1]
        self.bad_qd, self.nonfinite = s.bad[k + 1], s.bad[k + 2]
        self.ok = np.zeros(n, dtype=bool)
        self.tmp = np.zeros(n)
        self.now = np.zeros(n)
        self.mask = np.zeros(n, dtype=bool)
        self.saved = np.zeros((3, n))
        self.tmp_kn = np.zeros((k, n))
        self.tmp_lkn = np.zeros((L, k, n))
        self.m_lkn = np.zeros((L, k + 1, n), dtype=bool)
        self.saved_time = np.zeros((2, L, k + 1, n))

    # ------------------------------------------------------------------ features

    def features(self, qd: np.ndarray, dt: float) -> None:
        """Advance accel, moving, reversal, still by dt [s] on qd (n,) [rad/s]; joints whose
        qd is not finite keep their accel, moving and reversal and use their last finite qd."""
        s, ok, bad = self.s, self.ok, self.bad_qd
        np.isfinite(qd, out=ok)
        np.logical_not(ok, out=bad)
        if s.sst[ST_STARTED] == 0.0:
            self.qd_prev.fill(0.0)
            np.copyto(self.qd_prev, qd, where=ok)
            s.sst[ST_STARTED] = 1.0
        qd_ok = self.qd_ok
        np.copyto(qd_ok, qd)
        if not bad.any():  # the common case: nothing to hold
            self._advance(qd_ok, dt)
            return
        np.copyto(qd_ok, self.qd_prev, where=bad)
        saved = self.saved
        np.copyto(saved[0], self.accel)
        np.copyto(saved[1], self.moving)
        np.copyto(saved[2], self.reversal)
        self._advance(qd_ok, dt)
        np.copyto(self.accel, saved[0], where=bad)
        np.copyto(self.moving, saved[1], where=bad)
        np.copyto(self.reversal, saved[2], where=bad)

    def _advance(self, qd: np.ndarray, dt: float) -> None:
        tmp = self.tmp
        # low-passed acceleration: a += alpha·((qd - qd_prev)/dt - a)
        np.subtract(qd, self.qd_prev, out=tmp)
        tmp *= 1.0 / dt
        tmp -= self.accel
        tmp *= dt / (self.tau_a + dt)
        self.accel += tmp
        self.qd_prev[:] = qd
        # moving indicator: 1 while |qd| > v_rev, then decaying with moving_time
        np.abs(qd, out=tmp)
        np.greater(tmp, self.v_rev, out=self.mask)
        self.moving *= math.exp(-dt / self.moving_time)
        np.maximum(self.moving, self.mask, out=self.moving)
        # reversal: max(exp(-(qd/v_rev)²)·moving, decayed previous value)
        np.multiply(qd, 1.0 / self.v_rev, out=tmp)
        np.square(tmp, out=tmp)
        np.negative(tmp, out=tmp)
        np.exp(tmp, out=tmp)
        tmp *= self.moving
        self.reversal *= math.exp(-dt / self.reversal_time)
        np.maximum(self.reversal, tmp, out=self.reversal)
        # standstill s = exp(-(qd/v_s)²), rising with standstill_time T after a stop
        now = self.now
        np.multiply(qd, 1.0 / self.v_still, out=now)
        np.square(now, out=now)
        np.negative(now, out=now)
        np.exp(now, out=now)
        T = self.still_time
        if T <= 0.0:
            np.copyto(self.still, now)
            return
        np.subtract(now, self.still, out=tmp)
        tmp *= 1.0 - math.exp(-dt / T)
        tmp += self.still
        np.minimum(now, tmp, out=self.still)

    # ------------------------------------------------------------------ one tick

    def __call__(
        self, tau: np.ndarray, qd: np.ndarray, qdd: np.ndarray, dt: float, tick: int
    ) -> None:
        """tau (k, n) [N·m], qd (n,) [rad/s], qdd (n,) reference acceleration [rad/s²]."""
        s, k, L = self.s, self.k, self.L
        self.features(qd, dt)
        # non-finite estimates
        bad_tau = self.bad_tau
        np.isfinite(tau, out=bad_tau)
        np.logical_not(bad_tau, out=bad_tau)
        np.logical_or.reduce(bad_tau, axis=0, out=self.nonfinite)
        np.logical_or(self.nonfinite, self.bad_qd, out=self.nonfinite)
        any_bad = bool(self.nonfinite.any())
        s.hits[L] = any_bad
        if self.logic == "mean":
            self.bad_fused.fill(False)
            for r in self.dec:
                np.logical_or(self.bad_fused, bad_tau[r], out=self.bad_fused)
        # phase: acceleration while any |qdd_ref| > level, and phase_hold after
        fast = False
        if self.phased:
            np.abs(qdd, out=self.tmp)
            np.greater(self.tmp, self.accel_level, out=self.mask)
            fast = bool(self.mask.any())
        if fast:
            s.sst[ST_PHASE_LEFT] = self.phase_hold
        else:
            s.sst[ST_PHASE_LEFT] -= dt
        phase = 1 if s.sst[ST_PHASE_LEFT] > 0.0 else 0
        s.sst[ST_ACCEL_PHASE] = phase
        # thr = kv·|qd| + base + ka·|a| + kr·r + ks·s (this order: the sums are rounded)
        thr, t = self.thr, self.tmp_lkn
        np.abs(self.qd_ok, out=self.tmp)
        np.multiply(self.tmp, self.kv, out=thr)
        thr += self.base[phase]
        np.abs(self.accel, out=self.tmp)
        np.multiply(self.tmp, self.ka, out=t)
        thr += t
        np.multiply(self.reversal, self.kr, out=t)
        thr += t
        np.multiply(self.still, self.ks, out=t)
        thr += t
        # ratios (0 where the estimate is not finite), the fused mean row
        np.abs(tau, out=self.tmp_kn)
        if any_bad:
            np.copyto(self.tmp_kn, 0.0, where=bad_tau)
        np.divide(self.tmp_kn, thr, out=self.ratio_rows)
        if self.logic == "mean":
            fused = self.fused
            fused.fill(0.0)
            for r in self.dec:
                fused += self.row_ratio[r]
            fused /= len(self.dec)
            np.copyto(fused, 0.0, where=self.bad_fused)
        # debounce and hysteresis; a non-finite estimate neither trips nor releases
        above, below, m, saved = self.above, self.below, self.m_lkn, self.saved_time
        if any_bad:
            np.copyto(saved[0], above)
            np.copyto(saved[1], below)
        np.greater(self.ratio, 1.0, out=m)
        above += dt
        above *= m
        np.less(self.ratio, self.release_ratio, out=m)
        below += dt
        below *= m
        if any_bad:
            np.copyto(above, saved[0], where=self.bad_rows)
            np.copyto(below, saved[1], where=self.bad_rows)
        joints = s.joints
        np.greater_equal(above, self.trip_after, out=m)
        np.logical_or(joints, m, out=joints)
        np.greater_equal(below, self.release_after, out=m)
        np.logical_not(m, out=m)
        np.logical_and(joints, m, out=joints)
        # decisions
        np.logical_or.reduce(joints, axis=2, out=s.row_hit)
        for lv in range(L):
            self._decide(lv)
        hit = s.row_hit[L - 1]
        for r in range(k):
            if hit[r] and s.first_tick[r] < 0:
                s.first_tick[r] = tick

    def _decide(self, lv: int) -> None:
        s, k = self.s, self.k
        out = s.level_joints[lv]
        if self.logic == "mean":
            s.hits[lv] = s.row_hit[lv, k]
            np.copyto(out, s.joints[lv, k])
            return
        out.fill(False)
        hit = False
        every = True
        for r in self.dec:
            np.logical_or(out, s.joints[lv, r], out=out)
            if s.row_hit[lv, r]:
                hit = True
            else:
                every = False
        s.hits[lv] = hit and (every or self.logic == "any")


class ReferenceLevels:
    """``state``, ``backend`` and ``step`` of a CollisionLevels, run by :class:`NumpyStep`."""

    backend = "reference"

    def __init__(self, p: MonitorParams) -> None:
        from safety.collision.params import N_SCAL

        L, _, k, n = p.par.shape
        self.params, self.L = p, L
        self.state = s = MonitorState(L, k, n, N_SCAL)
        np.copyto(s.par, p.par)
        np.copyto(s.scal, p.scal)
        np.copyto(s.deciding, p.deciding)
        s.reset(p.par, None, float(p.scal[S_V_REV]))
        self._step = NumpyStep(p, s)

    def step(
        self, tau: np.ndarray, qd: np.ndarray, qdd: np.ndarray | None, dt: float, tick: int
    ) -> bool:
        n = qd.shape[0]
        self._step(tau, qd, np.zeros(n) if qdd is None else qdd, dt, tick)
        return bool(self.state.hits[self.L - 1])
