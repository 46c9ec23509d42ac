"""Emulated CANopen drives on python-can's virtual bus (one process), for the master tests."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from support.canopen import CanRig, load_cfg, unique_channel


@pytest.fixture()
def rig() -> Iterator[CanRig]:
    import can

    from drivers.sim.canopen_node import CanopenDrives
    from hofto_hw.runtime.build import build_emulated_drives as build_drives

    cfg = load_cfg()
    channel = unique_channel()
    bus = can.Bus(interface="virtual", channel=channel)
    emu = CanopenDrives(build_drives(cfg, external=False), bus).start()
    r = CanRig(cfg, channel, emu)
    try:
        yield r
    finally:
        for m in r.masters:
            m.close()
        emu.stop()
        bus.shutdown()
