"""Per-axis commissioning state for ``status`` and the run summary: safe torque off and the
holding brake (issue 28). Slow path only (reads the process image, allocates)."""

from __future__ import annotations

from typing import Any

import numpy as np

from drivers.cia402.state_machine import State


def axes_state(system: Any) -> list[dict[str, Any]]:
    """Per axis: ``name``; ``sto`` (its safe torque off active, as its drive profile's source
    shows it in the process image; None where the source is not there: an object read by
    SDO or the drive state, which the loop does not judge while disabled); ``brake``
    ("closed" / "open" on the emulated drives, from their brake model; None on a real bus,
    where the stack does not see the brake yet)."""
    group = system.group
    seen = group.sto_in_image(np.zeros(group.n, dtype=bool), by_state=False)
    known = np.array([src.source == "input" for src in group.sto_sources])
    known &= group.present("digital_inputs")
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
        sto = bool(seen[i]) if known[i] else None
        out.append({"name": name, "sto": sto, "brake": brake})
    return out


def axes_text(axes: list[dict[str, Any]]) -> str:
    """One line: ``axes (STO, brake): joint_1 off/closed, ...``."""
    sto = {True: "ACTIVE", False: "off", None: "n/a"}
    parts = [f"{a['name']} {sto[a['sto']]}/{a['brake'] or 'n/a'}" for a in axes]
    return "axes (STO, brake): " + ", ".join(parts)
