"""The numpy reference of the drive group's read and commands, for agreement tests only: the
product runs the kernels of drivers/cia402/kernels.py (``read_si``, ``command_raw``),
compiled or as their Python source. Here the same conversions are written as the vector
calls of drivers/cia402/units.py over the canonical images' field views (what the drive
group ran as its ``numpy`` path before the kernels became its one implementation)."""

from __future__ import annotations

from typing import Any

import numpy as np

from drivers.cia402 import state_machine as sm
from drivers.cia402.fallbacks import torque_scale

#: what :func:`read` returns, in this order
READ_FIELDS = ("q", "qd", "tau", "current", "states")


def read(group: Any) -> dict[str, np.ndarray]:
    """``group``'s TxPDO (its transport's canonical image) in SI: q [rad], qd [rad/s],
    tau [N·m], current [A] (n,) and the state codes (uint8, n), in new arrays."""
    sc, t = group.scaling, group.transport
    tx, n = t.tx, group.n
    out = {f: np.zeros(n) for f in READ_FIELDS[:4]}
    out["states"] = np.zeros(n, dtype=np.uint8)
    sc.position_to_si(tx["position"], out["q"])
    sc.velocity_to_si(tx["velocity"], out["qd"])
    np.multiply(tx["torque"], torque_scale(sc, t.torque_from_current), out=out["tau"])
    sc.current_to_si(tx["current"], out["current"])
    sm.decode_states(tx["statusword"], out["states"], np.zeros(n, dtype=np.uint16))
    return out


def command(group: Any, what: str, target: np.ndarray, tau_offset: np.ndarray | None) -> None:
    """``what`` ("command_position" or "command_velocity") of ``group`` into its transport's
    RxPDO: the target position [rad] or velocity [rad/s] (n,) and, when given, the torque
    offset [N·m] (n,), rounded half to even and saturated to the raw types."""
    sc, rx = group.scaling, group.transport.rx
    if what == "command_position":
        sc.position_to_raw(target, rx["target_position"])
    else:
        sc.velocity_to_raw(target, rx["target_velocity"])
    if tau_offset is not None:
        sc.torque_to_raw(tau_offset, rx["torque_offset"])
