"""Joint supervision on measured values: soft position limits, velocity, torque, following
error, position jumps between ticks and non-finite values anywhere in the tick.

Each check reports the first offending joint and its value to the
:class:`~safety.stop.StopController`; the controller latches and decides. Allocation-free
(preallocated masks, ``out=`` everywhere). Units: rad, rad/s, N·m.

``backend`` ``numba``/``auto`` (the observers' conventions): a compiled scan
(:func:`safety.kernels.limits_quiet`) settles the usual tick where nothing is to be reported;
when anything is, the numpy reference path runs and reports, so reports are identical.
"""

from __future__ import annotations

import numpy as np

from hofto_hw.observers import kernels
from hofto_hw.observers.kernels import Backend
from safety.kernels import limits_quiet
from safety.stop import Fault, StopController


class LimitMonitor:
    """Limits per joint, arrays of shape (n,): ``lower``/``upper`` [rad] (soft limits),
    ``velocity`` [rad/s], ``torque`` [N·m]; ``following_error`` and ``position_jump`` [rad]."""

    def __init__(
        self,
        lower: np.ndarray,
        upper: np.ndarray,
        velocity: np.ndarray,
        torque: np.ndarray,
        following_error: float,
        position_jump: float,
        backend: Backend = "numpy",
    ) -> None:
        n = len(lower)
        self.n = n
        self.lower = np.asarray(lower, dtype=float).copy()
        self.upper = np.asarray(upper, dtype=float).copy()
        self.velocity = np.asarray(velocity, dtype=float).copy()
        self.torque = np.asarray(torque, dtype=float).copy()
        self.following_error = float(following_error)
        self.position_jump = float(position_jump)
        self.q_prev = np.zeros(n)
        self._have_prev = False
        self._d = np.zeros(n)
        self._allow = np.zeros(n)
        self._m = np.zeros(n, dtype=bool)
        self._m2 = np.zeros(n, dtype=bool)
        self._fin = np.zeros(n, dtype=bool)
        self.backend = kernels.ready(backend, self._warm)
        self._use_kernel = self.backend == "numba"

    def _warm(self) -> None:
        z = np.zeros(self.n)
        for on in (False, True):  # have_prev, fresh, tracking
            limits_quiet(
                z, z, z, z, self.lower, self.upper, self.velocity, self.torque,
                self.following_error, self.position_jump, z.copy(), on, on, on, 0.0,
            )  # fmt: skip

    @classmethod
    def from_config(cls, cfg: object, limits: object, backend: Backend = "numpy") -> LimitMonitor:
        """From ``safety.limits`` (LimitsSafetyConfig) and the model's JointLimits."""
        margin = cfg.position_margin  # type: ignore[attr-defined]
        vel = np.asarray(limits.velocity, dtype=float) * cfg.velocity_scale  # type: ignore[attr-defined]
        tau = np.asarray(limits.torque, dtype=float) * cfg.torque_scale  # type: ignore[attr-defined]
        if cfg.velocity is not None:  # type: ignore[attr-defined]
            vel = np.asarray(cfg.velocity, dtype=float)  # type: ignore[attr-defined]
        if cfg.torque is not None:  # type: ignore[attr-defined]
            tau = np.asarray(cfg.torque, dtype=float)  # type: ignore[attr-defined]
        return cls(
            np.asarray(limits.position_lower, dtype=float) + margin,  # type: ignore[attr-defined]
            np.asarray(limits.position_upper, dtype=float) - margin,  # type: ignore[attr-defined]
            vel,
            tau,
            cfg.following_error,  # type: ignore[attr-defined]
            cfg.position_jump,  # type: ignore[attr-defined]
            backend,
        )

    def reset(self, q: np.ndarray) -> None:
        """Start from the measured position ``q`` (no jump is seen against it)."""
        np.copyto(self.q_prev, q)
        self._have_prev = True

    def finite(self, stop: StopController, x: np.ndarray) -> bool:
        """Report NON_FINITE (on the first bad joint) unless every entry of ``x`` (n,) is
        finite; returns whether all were."""
        if self._all_finite(x):
            return True
        j = int(np.argmin(self._fin))
        stop.report(Fault.NON_FINITE, j, float(x[j]))
        return False

    def _all_finite(self, x: np.ndarray) -> bool:
        np.isfinite(x, out=self._fin)
        return bool(self._fin.all())

    def check(
        self,
        stop: StopController,
        q: np.ndarray,
        qd: np.ndarray,
        tau: np.ndarray,
        q_cmd: np.ndarray,
        fresh: bool,
        tracking: bool,
        gap: float = 0.0,
    ) -> None:
        """One tick of limit checks on measured q, qd, tau and last tick's command q_cmd.

        ``fresh``: the sample is new this tick (jumps are only checked on fresh data);
        ``gap`` [s]: time between the previous fresh sample and this one beyond one bus
        cycle (a stale exchange or a stalled loop in between): the jump allowance grows by
        what each joint's velocity limit covers in it (``position_jump`` stays the bound for
        consecutive samples);
        ``tracking``: the drives are powered and follow q_cmd (following error and motor
        torque are checked only then: with the power stage off the brakes hold the arm).
        """
        if self._use_kernel:
            r = limits_quiet(
                q, qd, tau, q_cmd, self.lower, self.upper, self.velocity, self.torque,
                self.following_error, self.position_jump, self.q_prev, self._have_prev,
                fresh, tracking, gap,
            )  # fmt: skip
            if r:
                if r == 2:
                    self._have_prev = True
                return
        self._check_numpy(stop, q, qd, tau, q_cmd, fresh, tracking, gap)

    def _check_numpy(
        self,
        stop: StopController,
        q: np.ndarray,
        qd: np.ndarray,
        tau: np.ndarray,
        q_cmd: np.ndarray,
        fresh: bool,
        tracking: bool,
        gap: float = 0.0,
    ) -> None:
        """The reference path of :meth:`check` (it reports)."""
        d, m, m2 = self._d, self._m, self._m2
        np.less(q, self.lower, out=m)
        np.greater(q, self.upper, out=m2)
        np.logical_or(m, m2, out=m)
        if m.any():
            j = int(np.argmax(m))
            stop.report(Fault.POSITION_LIMIT, j, float(q[j]))
        np.abs(qd, out=d)
        np.greater(d, self.velocity, out=m)
        if m.any():
            j = int(np.argmax(m))
            stop.report(Fault.VELOCITY_LIMIT, j, float(qd[j]))
        if tracking:
            np.abs(tau, out=d)
            np.greater(d, self.torque, out=m)
            if m.any():
                j = int(np.argmax(m))
                stop.report(Fault.TORQUE_LIMIT, j, float(tau[j]))
            np.subtract(q_cmd, q, out=d)
            np.abs(d, out=d)
            np.greater(d, self.following_error, out=m)
            if m.any():
                j = int(np.argmax(m))
                stop.report(Fault.FOLLOWING_ERROR, j, float(d[j]))
        if fresh:
            if self._have_prev:
                np.subtract(q, self.q_prev, out=d)
                np.abs(d, out=d)
                if gap > 0.0:
                    np.multiply(self.velocity, gap, out=self._allow)
                    self._allow += self.position_jump
                    np.greater(d, self._allow, out=m)
                else:
                    np.greater(d, self.position_jump, out=m)
                if m.any():
                    j = int(np.argmax(m))
                    stop.report(Fault.POSITION_JUMP, j, float(d[j]))
            if self._all_finite(q):
                np.copyto(self.q_prev, q)
                self._have_prev = True
