"""Per-axis commissioning state for ``status``, ``Robot.state()`` and the run summary: safe
torque off and the holding brake (issue 28).

:class:`AxesState` reads them from the process image (and, on the simulated bus, from the
emulated drives' brake model) into caller-owned arrays without allocating: the control
plane's port fills the channel's per-axis words with it after every tick. :func:`axes_state`
is the same reading as a list of dicts (the summary; slow path)."""

from __future__ import annotations

from typing import Any

import numpy as np

from drivers.cia402.state_machine import State

#: STO and brake codes of :meth:`AxesState.fill` (float: they travel as float64 words)
STO_UNKNOWN, STO_OFF, STO_ACTIVE = -1.0, 0.0, 1.0
BRAKE_UNKNOWN, BRAKE_OPEN, BRAKE_CLOSED = -1.0, 0.0, 1.0
BRAKE_NAMES = {BRAKE_OPEN: "open", BRAKE_CLOSED: "closed"}
STO_NAMES = {STO_OFF: False, STO_ACTIVE: True}


class AxesState:
    """STO and brake per axis of ``system`` (its ``group``, ``bus``, ``cfg``).

    ``sto``: as the axis's drive profile names its source (``DriveGroup.sto_in_image``),
    where that source is in the process image (a 0x60FD bit that is mapped); unknown where it
    is an object read by SDO or the drive state, which the loop does not judge while
    disabled. ``brake``: "closed" / "open" on the emulated drives, from their brake model (a
    drive without a modelled brake closes its ideal brake whenever the power stage is off);
    unknown on a real bus, where the stack does not see the brake."""

    def __init__(self, system: Any) -> None:
        group = system.group
        n = group.n
        self.n = n
        self.names = list(system.cfg.robot.joints)
        self._group = group
        known = np.array([src.source == "input" for src in group.sto_sources], dtype=bool)
        self._sto_unknown = ~(known & group.present("digital_inputs"))
        drives = getattr(system.bus, "drives", None)  # the SimBus's emulated drives
        self._sim = drives if hasattr(drives, "real_brake") else None
        self._m = np.zeros(n, dtype=bool)

    def fill(self, sto: np.ndarray, brake: np.ndarray) -> None:
        """STO codes (``STO_*``) and brake codes (``BRAKE_*``) into float64 (n,) arrays;
        allocates nothing."""
        self._group.sto_in_image(self._m, by_state=False)
        np.copyto(sto, self._m)  # True: STO_ACTIVE (1.0), False: STO_OFF (0.0)
        np.copyto(sto, STO_UNKNOWN, where=self._sto_unknown)
        d = self._sim
        if d is None:
            brake.fill(BRAKE_UNKNOWN)
            return
        # the modelled brake's state, else the ideal brake: closed unless operation enabled
        # the group's states read now: the fused tick may move its arrays into its record
        np.not_equal(self._group.states, int(State.OPERATION_ENABLED), out=self._m)
        np.copyto(self._m, d.brake_engaged, where=d.real_brake)
        np.copyto(brake, self._m)  # True: BRAKE_CLOSED (1.0), False: BRAKE_OPEN (0.0)


def axes_of(names: list[str], sto: np.ndarray, brake: np.ndarray) -> list[dict[str, Any]]:
    """The per-axis words as ``[{"name", "sto": bool|None, "brake": "closed"|"open"|None}]``."""
    return [
        {
            "name": name,
            "sto": STO_NAMES.get(float(sto[i])),
            "brake": BRAKE_NAMES.get(float(brake[i])),
        }
        for i, name in enumerate(names)
    ]


def axes_state(system: Any) -> list[dict[str, Any]]:
    """Per axis: ``name``; ``sto``; ``brake`` (see :class:`AxesState`)."""
    a = AxesState(system)
    sto, brake = np.zeros(a.n), np.zeros(a.n)
    a.fill(sto, brake)
    return axes_of(a.names, sto, brake)


def axes_text(axes: list[dict[str, Any]]) -> str:
    """One line: ``axes (STO, brake): joint_1 off/closed, ...``."""
    sto = {True: "ACTIVE", False: "off", None: "n/a"}
    parts = [f"{a['name']} {sto[a['sto']]}/{a['brake'] or 'n/a'}" for a in axes]
    return "axes (STO, brake): " + ", ".join(parts)
