"""Helpers for the CANopen tests: unique channels, waiting for states, the test rig."""

from __future__ import annotations

import itertools
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "configs" / "er3a_canopen.yaml"
RATE_HZ = 200.0
_counter = itertools.count()


def unique_channel(prefix: str = "hofto") -> str:
    """A virtual-bus channel name no other test (or process) uses."""
    return f"{prefix}-{os.getpid()}-{next(_counter)}"


def wait_for(cond: Callable[[], bool], timeout: float = 10.0, what: str = "condition") -> None:
    """Wait for a state (not a time): fail with ``what`` when it does not come."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return
        time.sleep(0.005)
    raise AssertionError(f"timed out waiting for {what}")


@dataclass
class CanRig:
    """Config, emulated drives (thread) and a factory for masters on one virtual channel."""

    cfg: Any
    channel: str
    emu: Any
    masters: list[Any] = field(default_factory=list)

    def master(self, **kw: Any) -> Any:
        from drivers.canopen.master import CANopenTransport

        kw.setdefault("tpdo_deadline", 0.05)  # generous: CI is a loaded 2-core machine
        kw.setdefault("heartbeat_time", 0.05)
        kw.setdefault("heartbeat_timeout", 0.5)
        kw.setdefault("sdo_timeout", 2.0)
        t = CANopenTransport(
            self.channel,
            self.cfg.bus.drives,
            1.0 / self.cfg.loop.rate_hz,
            list(self.cfg.robot.joints),
            can_interface="virtual",
            **kw,
        )
        self.masters.append(t)
        return t

    def call(self, **request: Any) -> dict:
        reply = self.emu.control(request)
        assert reply["ok"], reply
        return reply


def load_cfg() -> Any:
    from hofto_hw.config.loader import load_config

    return load_config(CONFIG)
