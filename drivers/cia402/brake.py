"""Holding-brake test of one axis, as a per-cycle sequence the caller steps.

With the brake closed and the drive powered in cyclic synchronous torque (CST), the caller
commands the gravity torque (so the brake carries only the test) plus :attr:`BrakeTest.torque`:
a ramp to +T, a hold, a ramp to −T, a hold, a ramp back to 0, T = ``fraction`` of the brake's
rated holding torque. The brake held when the joint stayed within ``bound`` [rad] of where it
started; else one line names the joint, how far it moved and under which torque (a worn or
contaminated brake slips). This is the integrator's check before putting an arm in service.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class BrakeTestPlan:
    """axis, its name, test torque T [N·m], ramp and hold times [cycles], motion bound [rad]."""

    axis: int
    name: str
    torque: float
    ramp_cycles: int
    hold_cycles: int
    bound: float = 5e-3


def brake_test_plan(
    axis: int,
    name: str,
    holding_torque: float,
    fraction: float,
    cycle_time: float,
    ramp: float = 0.2,
    hold: float = 0.5,
    bound: float = 5e-3,
) -> BrakeTestPlan:
    """A plan applying ``fraction`` (0, 1] of the rated ``holding_torque`` [N·m]."""
    if not (0.0 < fraction <= 1.0):
        raise ValueError(f"brake test torque fraction must be in (0, 1], got {fraction}")
    if not holding_torque > 0.0:
        raise ValueError(f"holding torque must be > 0 N·m, got {holding_torque}")
    return BrakeTestPlan(
        axis,
        name,
        fraction * holding_torque,
        max(1, round(ramp / cycle_time)),
        max(1, round(hold / cycle_time)),
        bound,
    )


class BrakeTest:
    """Steps the torque profile; ``result`` None while running, "" held, else one line."""

    def __init__(self, plan: BrakeTestPlan) -> None:
        self.plan = plan
        r, h = plan.ramp_cycles, plan.hold_cycles
        # (cycles, torque at the start, torque at the end) of each segment
        t = plan.torque
        self._segments = [(r, 0.0, t), (h, t, t), (2 * r, t, -t), (h, -t, -t), (r, -t, 0.0)]
        self._seg = 0
        self._k = 0
        self._q0: float | None = None
        self.torque = 0.0
        self.torque_before = 0.0  # the torque the joint was under when it was measured
        self.worst = 0.0
        self.result: str | None = None

    @property
    def done(self) -> bool:
        return self.result is not None

    def step(self, q: float) -> None:
        """One cycle with the joint position ``q`` [rad]; sets :attr:`torque` for the next."""
        if self.result is not None:
            return
        if self._q0 is None:
            self._q0 = q
        moved = q - self._q0
        if abs(moved) > abs(self.worst):
            self.worst = moved
        p = self.plan
        if abs(moved) > p.bound:
            self.torque = 0.0
            self.result = (
                f"{p.name}: the brake slipped: the joint moved {moved * 1e3:+.2f} mrad under "
                f"{self.torque_before:+.1f} N·m (test torque {p.torque:.1f} N·m, bound "
                f"{p.bound * 1e3:g} mrad)"
            )
            return
        self.torque_before = self.torque
        n, a, b = self._segments[self._seg]
        self._k += 1
        self.torque = a + (b - a) * min(self._k / n, 1.0)
        if self._k >= n:
            self._seg += 1
            self._k = 0
            if self._seg == len(self._segments):
                self.torque = 0.0
                self.result = ""


class ReleaseCheck:
    """The brake release check of every braked axis, stepped once per cycle: after the
    drives reached Operation enabled (the gravity preload already in the torque offset),
    the caller holds the position the check started at for ``cycles`` cycles (the longest
    release delay plus a few); then an axis that moved more than its ``bounds`` [rad] is a
    brake that did not release cleanly (the load not held, or the brake drags).

    Used at start-up (``runtime/compose``) and by the loop on every re-enable after a reset.
    :meth:`step` allocates nothing.
    """

    RUNNING = -2
    PASSED = -1

    def __init__(self, axes: np.ndarray, bounds: np.ndarray, cycles: int) -> None:
        self.axes = np.asarray(axes, dtype=np.intp)
        self.bounds = np.asarray(bounds, dtype=float)  # per entry of ``axes`` [rad]
        self.cycles = max(1, int(cycles))
        self.q0 = np.zeros(0)
        self.count = 0
        self.moved = 0.0  # [rad] of the axis that failed, else of the last step's largest

    @classmethod
    def from_drives(cls, drives: list[Any], cycle_time: float) -> ReleaseCheck | None:
        """For the ``bus.drives`` entries with a ``brake`` (None when there is none)."""
        axes = [i for i, d in enumerate(drives) if getattr(d, "brake", None) is not None]
        if not axes:
            return None
        bounds = [drives[i].brake.release_bound for i in axes]
        wait = max(drives[i].brake.release_delay for i in axes)
        return cls(np.array(axes), np.array(bounds), int(np.ceil(wait / cycle_time)) + 3)

    def start(self, q: np.ndarray) -> None:
        """Begin at the measured joint positions ``q`` [rad] (n,): the ones to hold."""
        if self.q0.shape != q.shape:
            self.q0 = np.zeros_like(q)
        np.copyto(self.q0, q)
        self.count = 0

    def step(self, q: np.ndarray) -> int:
        """One cycle: RUNNING, then PASSED or the first axis that moved beyond its bound
        (its motion in :attr:`moved`, signed)."""
        self.count += 1
        if self.count < self.cycles:
            return self.RUNNING
        for k in range(self.axes.shape[0]):
            i = self.axes[k]
            d = float(q[i] - self.q0[i])
            if abs(d) > self.bounds[k]:
                self.moved = d
                return int(i)
        return self.PASSED
