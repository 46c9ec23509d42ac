"""CiA 402 homing run by the service's loop (``hofto-hw home`` through the control plane).

The control plane's port starts it between two ticks (:meth:`LoopHoming.begin`, after its
checks: nothing latched, holding at rest, powered); the tick then calls :meth:`step` once per
tick, before its safety checks, until it answers True. Each axis in turn goes through
:class:`drivers.cia402.homing.HomingSequence` (mode 6 with the start bit, back to the loop's
mode). While an axis homes, the drive moves it, not the loop: its reference, last command and
the limit monitor's last position follow the measured angle (no following error, no position
jump when the drive sets its position at home; the position and velocity limits still
apply), and the collision monitor does not judge (the tick's ``homing`` check). A stop aborts
it: the axis is given back its loop mode and the result names the axis.

The homing objects (0x6098, 0x6099, 0x609A, 0x607C) are written by SDO before the loop
starts (:func:`write_homing_objects`), never from a tick. Per tick nothing is allocated but
the result line at the end.
"""

from __future__ import annotations

from typing import Any

from drivers.cia402.homing import HomingPlan, HomingSequence, homing_plan


def homing_plans(cfg: Any, group: Any, cycle_time: float) -> dict[int, HomingPlan]:
    """The plan of every axis with ``homing:`` in ``cfg.bus.drives`` (axis -> plan)."""
    if cfg.bus is None:
        return {}
    names = list(cfg.robot.joints)
    return {
        i: homing_plan(d.homing, group.scaling, i, cycle_time, names[i], group.drive_units(i))
        for i, d in enumerate(cfg.bus.drives)
        if d.homing is not None
    }


def write_homing_objects(transport: Any, plans: dict[int, HomingPlan]) -> None:
    """Write each plan's homing objects by SDO (start-up, before the loop runs)."""
    for plan in plans.values():
        for index, sub, kind, value in plan.sdo_writes():
            transport.write_value(plan.axis, index, sub, kind, value)


class LoopHoming:
    """Homes a list of axes, one per tick step (see the module notes). ``result``: None while
    running, "" when every axis homed, else one line (the first failure; the axes after it
    are left alone). ``homed``: the names of the axes homed so far."""

    def __init__(self, group: Any, plans: dict[int, HomingPlan]) -> None:
        self.group = group
        self.plans = plans
        rx, tx = group.transport.rx, group.transport.tx
        self._cw, self._mode = rx["controlword"], rx["mode"]
        self._sw, self._md = tx["statusword"], tx["mode_display"]
        self._axes: list[int] = []
        self._k = 0
        self.seq: HomingSequence | None = None
        self.result: str | None = None
        self.homed: list[str] = []

    def begin(self, axes: list[int]) -> None:
        """Home ``axes`` (each with a plan) in this order (rare: allocates)."""
        self._axes = list(axes)
        self._k = 0
        self.result = None
        self.homed = []
        self._next()

    def _next(self) -> None:
        a = self._axes[self._k]
        self.seq = HomingSequence(self.plans[a], int(self._mode[a]))

    def step(self, tick: Any) -> bool:
        """One tick (the tick's joint state read); True when finished (``result`` set)."""
        seq = self.seq
        assert seq is not None
        a = seq.plan.axis
        g = self.group
        if tick.stop.category != -1 or tick.stop_requested:
            self._mode[a] = seq.loop_mode  # the tick's stop commands the controlword
            self._follow(tick, a)
            self.result = f"{seq.plan.name}: homing interrupted by a stop"
            return True
        seq.step(int(self._sw[a]), int(self._md[a]), float(g.q[a]))
        self._cw[a] = seq.controlword
        self._mode[a] = seq.mode
        self._follow(tick, a)
        if not seq.done:
            return False
        if seq.result:
            self.result = seq.result
            return True
        self.homed.append(seq.plan.name)
        self._k += 1
        if self._k == len(self._axes):
            self.result = ""
            return True
        self._next()
        return False

    def _follow(self, tick: Any, a: int) -> None:
        """The homed axis's reference, last command and last monitored position: where the
        drive has it."""
        q = self.group.q[a]
        tick.motion.q[a] = q
        tick.q_sent[a] = q
        tick.limits.q_prev[a] = q
        tick.motion.version += 1
