"""Start-up order of ``hofto-hw run``: the drives are enabled only after every compiled kernel
is warmed and the start-up garbage is collected. An enabled drive whose bus carries no process
data for longer than its watchdog (EtherCAT SM watchdog, 100 ms by default) leaves Operation
enabled; over EtherCAT a cold kernel cache (seconds of compiling) between the enable and the
loop's first tick latched ``drive_disabled`` in tick 1, and the arm then never stopped on a
collision (the monitor judges powered drives only)."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.cia402.state_machine import State
from hofto_hw import jit
from hofto_hw.config.models import SystemConfig
from hofto_hw.runtime import compose


def test_drives_are_enabled_after_the_warm_up_and_the_collection(
    cfg: SystemConfig, monkeypatch: pytest.MonkeyPatch
) -> None:
    groups = []
    seen: list[tuple[str, bool]] = []
    build_bus = compose.build_bus

    def capture(*args, **kw):
        bus, group = build_bus(*args, **kw)
        groups.append(group)
        return bus, group

    def enabled() -> bool:
        return bool(groups) and bool(np.any(groups[0].states == State.OPERATION_ENABLED))

    warm = jit.warm

    def watch_warm(fn):
        seen.append(("warm", enabled()))
        return warm(fn)

    collect = compose.collect_before_loop

    def watch_collect() -> None:
        seen.append(("collect", enabled()))
        collect()

    monkeypatch.setattr(compose, "build_bus", capture)
    monkeypatch.setattr(jit, "warm", watch_warm)
    monkeypatch.setattr(compose, "collect_before_loop", watch_collect)
    system = compose.build(cfg, clock="real", contact=False)
    try:
        assert system.tick.expect_enabled and system.group.all_in(State.OPERATION_ENABLED)
        assert ("collect", False) in seen, seen
        late = [what for what, on in seen if on]
        assert not late, f"after the drives were enabled: {late}"
    finally:
        system.close()


def test_the_helpers_are_awaited_after_the_kernels_before_the_bus_opens(
    cfg: SystemConfig, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``before_bus`` (where ``hofto-hw run`` awaits its writer and control plane) runs once
    the observers' kernels are loaded and before the bus opens: a wait between opening a real
    bus and enabling would hold back its process data past the drives' watchdog."""
    seen: list[str] = []
    build_bus = compose.build_bus
    make_observer = compose.make_observer

    def watch_bus(*args, **kw):
        seen.append("bus")
        return build_bus(*args, **kw)

    def watch_observer(*args, **kw):
        seen.append("observer")
        return make_observer(*args, **kw)

    monkeypatch.setattr(compose, "build_bus", watch_bus)
    monkeypatch.setattr(compose, "make_observer", watch_observer)
    system = compose.build(cfg, contact=False, before_bus=lambda: seen.append("helpers"))
    try:
        assert seen.count("helpers") == 1, seen
        at = seen.index("helpers")
        assert "observer" in seen[:at] and seen[at + 1 :] == ["bus"], seen
    finally:
        system.close()
