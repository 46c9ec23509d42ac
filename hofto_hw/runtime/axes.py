"""Per-axis commissioning state for ``status`` and the run summary: safe torque off and the
holding brake (issue 28). Slow path only (reads the process image, allocates)."""

from __future__ import annotations

from typing import Any

from drivers.cia402 import state_machine as sm
from drivers.cia402.state_machine import State


def axes_state(system: Any) -> list[dict[str, Any]]:
    """Per axis: ``name``; ``sto`` (0x60FD safe torque off input active); ``brake``
    ("closed" / "open" on the emulated drives, from their brake model; None on a real bus,
    where the stack does not see the brake yet)."""
    group = system.group
    din = group.transport.tx["digital_inputs"]
    drives = getattr(system.bus, "drives", None)  # the SimBus's emulated drives
    if not hasattr(drives, "real_brake"):  # a real bus (its .drives, if any, is not the model)
        drives = None
    out = []
    for i, name in enumerate(system.cfg.robot.joints):
        brake = None
        if drives is not None:
            if drives.real_brake[i]:
                closed = bool(drives.brake_engaged[i])
            else:  # the ideal brake closes whenever the power stage is off
                closed = int(group.states[i]) != State.OPERATION_ENABLED
            brake = "closed" if closed else "open"
        out.append({"name": name, "sto": bool(int(din[i]) & sm.DIN_STO), "brake": brake})
    return out


def axes_text(axes: list[dict[str, Any]]) -> str:
    """One line: ``axes (STO, brake): joint_1 off/closed, ...``."""
    parts = [f"{a['name']} {'ACTIVE' if a['sto'] else 'off'}/{a['brake'] or 'n/a'}" for a in axes]
    return "axes (STO, brake): " + ", ".join(parts)
