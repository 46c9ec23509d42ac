"""CiA 402 homing of one axis (mode 6), as a per-cycle sequence the caller steps.

:func:`homing_plan` turns an axis's ``homing:`` config (SI, joint side) into the raw values
of 0x6098 (method), 0x6099:1/2 (speeds, counts/s), 0x609A (acceleration, counts/s²; both
in the drive's own units when its profile says rpm, rpm/s or rev/s²:
:meth:`DriveGroup.drive_units`) and 0x607C (home offset, counts) for the SDO writes
(:meth:`HomingPlan.sdo_writes`). A
:class:`HomingSequence` is then stepped once per bus cycle with the axis's statusword,
mode display and position [rad]; it gives the controlword and mode to send:

1. mode 6 with "enable operation" until the drive displays mode 6;
2. controlword bit 4 set (start) until the statusword says homing attained and target
   reached (bits 12 and 10), homing error (bit 13), or the timeout (counted in cycles, not
   wall time);
3. bit 4 cleared and the loop's mode back until the drive displays it.

The result is ``None`` while running, then "" (homed at the expected position) or one line
naming the axis and what went wrong: timeout, homing error, end position away from the
configured offset by more than its tolerance, drive not operation enabled. Whether homing may
start at all (nothing latched, the arm at rest) is the caller's decision.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from drivers.cia402 import state_machine as sm
from drivers.cia402.state_machine import Mode
from drivers.cia402.units import Scaling
from hofto_hw.config.drives import HomingConfig

if TYPE_CHECKING:
    from drivers.cia402.drive_group import DriveGroup

_MODE, _START, _RESTORE, _DONE = range(4)


@dataclass(frozen=True)
class HomingPlan:
    """Raw homing objects of one axis and its limits (see the module notes)."""

    axis: int
    name: str
    method: int
    speeds: tuple[int, int]  # counts/s, or the drive's velocity unit (rpm)
    acceleration: int  # counts/s², or the drive's acceleration unit (rpm/s, rev/s²)
    home_offset: int  # counts
    offset: float  # joint angle at home [rad]
    tolerance: float  # [rad]
    timeout_cycles: int

    def sdo_writes(self) -> list[tuple[int, int, str, int]]:
        """(index, subindex, data type, raw value) to write before homing."""
        return [
            (0x6098, 0, "i8", self.method),
            (0x6099, 1, "u32", self.speeds[0]),
            (0x6099, 2, "u32", self.speeds[1]),
            (0x609A, 0, "u32", self.acceleration),
            (0x607C, 0, "i32", self.home_offset),
        ]


def homing_plan(
    cfg: HomingConfig,
    scaling: Scaling,
    axis: int,
    cycle_time: float,
    name: str = "",
    units: tuple[float, float] = (1.0, 1.0),
) -> HomingPlan:
    """The raw plan for axis ``axis`` from its config; ``cycle_time`` [s] of the bus;
    ``units``: counts/s per unit of the drive's velocities and counts/s² per unit of its
    accelerations (:meth:`DriveGroup.drive_units`: rpm, rpm/s, rev/s² when its profile
    says so), the units 0x6099 and 0x609A are written in (at least 1: a speed that rounds
    to 0 would never end)."""
    home = round(float(scaling.zero_offset[axis]) + cfg.offset * float(scaling.count_per_rad[axis]))
    fast, slow = (max(1, scaling.speed_to_raw(axis, v, units[0])) for v in cfg.speeds)
    return HomingPlan(
        axis=axis,
        name=name or f"axis {axis}",
        method=int(cfg.method),
        speeds=(fast, slow),
        acceleration=max(1, scaling.acceleration_to_raw(axis, cfg.acceleration, units[1])),
        home_offset=int(home),
        offset=float(cfg.offset),
        tolerance=float(cfg.tolerance),
        timeout_cycles=max(1, math.ceil(cfg.timeout / cycle_time)),
    )


class HomingSequence:
    """Steps one axis through homing and back to ``loop_mode`` (see the module notes)."""

    def __init__(self, plan: HomingPlan, loop_mode: int = int(Mode.CSP)) -> None:
        self.plan = plan
        self.loop_mode = int(loop_mode)
        self.controlword = sm.CW_ENABLE_OPERATION
        self.mode = int(Mode.HOMING)
        self.result: str | None = None
        self._phase = _MODE
        self._cycles = 0
        self._failure = ""

    @property
    def done(self) -> bool:
        return self._phase == _DONE

    def step(self, statusword: int, mode_display: int, position: float) -> None:
        """One bus cycle: the axis's statusword, 0x6061 and position [rad]."""
        if self._phase == _DONE:
            return
        p = self.plan
        self._cycles += 1
        if sm.decode_state(statusword) != sm.State.OPERATION_ENABLED:
            self._finish(
                f"{p.name}: homing needs operation enabled, the drive is "
                f"{sm.describe_statusword(statusword)}"
            )
            return
        if self._cycles > p.timeout_cycles and self._phase != _RESTORE:
            seconds = "the configured timeout"
            self._finish(
                f"{p.name}: homing (method {p.method}) did not end within {seconds} "
                f"({p.timeout_cycles} cycles); position {position:.4f} rad"
            )
            return
        if self._phase == _MODE:
            if mode_display == int(Mode.HOMING):
                self._phase = _START
                self.controlword = sm.CW_ENABLE_OPERATION | sm.CW_HOMING_START
            return
        if self._phase == _START:
            if statusword & sm.SW_HOMING_ERROR:
                self._finish(
                    f"{p.name}: the drive reports homing error (method {p.method}); "
                    f"position {position:.4f} rad"
                )
            elif statusword & sm.SW_HOMING_ATTAINED and statusword & sm.SW_TARGET_REACHED:
                miss = position - p.offset
                if abs(miss) > p.tolerance:
                    self._finish(
                        f"{p.name}: homing ended at {position:.4f} rad, "
                        f"{miss:+.4f} rad from the home offset {p.offset:.4f} rad "
                        f"(tolerance {p.tolerance:g} rad)"
                    )
                else:
                    self._finish("")
            return
        if self._phase == _RESTORE and mode_display == self.loop_mode:
            self._phase = _DONE
            self.result = self._failure

    def _finish(self, failure: str) -> None:
        self._failure = failure
        self.controlword = sm.CW_ENABLE_OPERATION
        self.mode = self.loop_mode
        self._phase = _RESTORE
        if failure and "operation enabled" in failure:
            self._phase = _DONE  # nothing to restore on a drive that is not enabled
            self.result = failure


def home_axes(group: DriveGroup, plans: list[HomingPlan], loop_mode: int | None = None) -> str:
    """Home the axes of ``plans`` one after the other on an enabled ``group`` (every other
    axis holds its measured position); "" when all homed, else the first failure (one line)
    and the axes after it are left alone. Each plan's objects are written by SDO first.
    Each axis goes back to ``loop_mode``, by default the mode it ran before (an axis whose
    drive runs the loop's CSP in profile velocity or ip goes back to that mode, not 8)."""
    t = group.transport
    rx, tx = t.rx, t.tx
    for plan in plans:
        a = plan.axis
        back = (int(rx["mode"][a]) or int(Mode.CSP)) if loop_mode is None else int(loop_mode)
        for index, sub, kind, value in plan.sdo_writes():
            t.write_value(a, index, sub, kind, value)
        seq = HomingSequence(plan, back)
        while not seq.done:
            group.hold()
            rx["controlword"][a] = seq.controlword
            rx["mode"][a] = seq.mode
            t.wait_next_cycle()
            group.cycle()
            seq.step(int(tx["statusword"][a]), int(tx["mode_display"][a]), float(group.q[a]))
        rx["controlword"][a] = seq.controlword
        rx["mode"][a] = back
        if seq.result:
            return seq.result
    return ""
