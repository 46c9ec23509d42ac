"""The numpy references of the bus and limit checks, for the agreement tests only (the
product's one implementation is safety/kernels.py, on the workspaces of
safety.bus_health.BusHealth and safety.limits.LimitMonitor; tests/safety/test_kernels.py
compares every report of tests/support/reference_safety.py's calls with these)."""

from __future__ import annotations

import numpy as np

from safety.stop import Fault, StopController


class ReferenceLimits:
    """reference_safety.limits_check as numpy calls on the limits (n,) [rad, rad/s, N·m] and
    bounds."""

    def __init__(
        self,
        lower: np.ndarray,
        upper: np.ndarray,
        velocity: np.ndarray,
        torque: np.ndarray,
        following_error: float,
        position_jump: float,
    ) -> None:
        self.lower, self.upper = np.array(lower, float), np.array(upper, float)
        self.velocity, self.torque = np.array(velocity, float), np.array(torque, float)
        self.following_error, self.position_jump = following_error, position_jump
        n = len(lower)
        self.q_prev = np.zeros(n)
        self.have_prev = False
        self._d, self._allow = np.zeros(n), np.zeros(n)
        self._m, self._m2 = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)

    def reset(self, q: np.ndarray) -> None:
        np.copyto(self.q_prev, q)
        self.have_prev = True

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
        if tracking and fresh:  # a stale sample's lag is an old q against a newer q_cmd
            np.subtract(q_cmd, q, out=d)
            np.abs(d, out=d)
            np.greater(d, self.following_error, out=m)
            if m.any():
                j = int(np.argmax(m))
                stop.report(Fault.FOLLOWING_ERROR, j, float(d[j]))
        if fresh:
            if self.have_prev:
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
            if np.all(np.isfinite(q)):
                np.copyto(self.q_prev, q)
                self.have_prev = True


class ReferenceBus:
    """reference_safety.bus_check's drive-state judgement as numpy calls (bus loss counted as
    there)."""

    def __init__(self, n: int, lost_cycles: int, op_enabled: int, fault_states: tuple[int, ...]):
        self.lost_cycles, self.op_enabled = lost_cycles, op_enabled
        self.fault_min = min(fault_states)
        self.streak = self.lost_total = 0
        self._m = np.zeros(n, dtype=bool)

    def check(
        self,
        stop: StopController,
        status: int,
        fresh: bool,
        states: np.ndarray,
        error_codes: np.ndarray,
        expect_enabled: bool,
    ) -> bool:
        if not (status == 0 and fresh):
            self.streak += 1
            self.lost_total += 1
            if self.streak >= self.lost_cycles:
                stop.report(Fault.BUS_LOSS, -1, float(status))
            return False
        self.streak = 0
        m = self._m
        np.greater_equal(states, self.fault_min, out=m)
        if m.any():
            j = int(np.argmax(m))
            stop.report(Fault.DRIVE_FAULT, j, float(int(error_codes[j])))
        elif expect_enabled:
            np.not_equal(states, self.op_enabled, out=m)
            if m.any():
                j = int(np.argmax(m))
                stop.report(Fault.DRIVE_DISABLED, j, float(states[j]))
        return True
