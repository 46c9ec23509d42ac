"""Six CANopen nodes of three drive profiles on one virtual bus: PDOs disabled by default
enabled by the master, fixed TPDOs, four entries per PDO, a mode set by a start-up SDO,
absent torque and error-code objects (EMCY), the CiA-402 group over the mixed image."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
from support.canopen import CONFIG, unique_channel, wait_for
from support.profiles import CAN_MIXED, CAN_TECHNOSOFT, profile, write_mixed_config

from drivers.canopen.errors import CANopenError
from drivers.cia402.drive_group import DriveGroup
from drivers.cia402.state_machine import Mode, State
from drivers.transport import STATUS_OK


@pytest.fixture()
def can_bus(tmp_path: Path):
    import can

    from drivers.sim.canopen_node import CanopenDrives
    from hofto_hw.config.loader import load_config
    from hofto_hw.runtime.build import build_emulated_drives

    cfg = load_config(write_mixed_config(tmp_path, CAN_MIXED, base=CONFIG))
    channel = unique_channel()
    bus = can.Bus(interface="virtual", channel=channel)
    emu = CanopenDrives(build_emulated_drives(cfg, external=False), bus).start()
    masters = []
    try:
        yield cfg, channel, emu, masters
    finally:
        for m in masters:
            m.close()
        emu.stop()
        bus.shutdown()


def _master(cfg, channel, masters, profiles=None):
    from drivers.canopen.master import CANopenTransport
    from drivers.cia402.profiles import profiles_for

    t = CANopenTransport(
        channel,
        cfg.bus.drives,
        1.0 / cfg.loop.rate_hz,
        list(cfg.robot.joints),
        can_interface="virtual",
        tpdo_deadline=0.05,
        heartbeat_time=0.05,
        heartbeat_timeout=0.5,
        sdo_timeout=2.0,
        profiles=profiles or profiles_for(cfg.bus.drives, "canopen"),
    )
    masters.append(t)
    return t


def test_three_profiles_run_mixed_on_one_bus(can_bus) -> None:
    cfg, channel, emu, masters = can_bus
    t = _master(cfg, channel, masters)
    t.open()
    assert t.startup_written == 2  # the two Faulhaber-like nodes' mode
    assert t.read_value(1, 0x6060, 0, "i8") == 8
    assert [t.wire.rx_size(i) for i in range(3)] == [13, 10, 14]
    assert [t.wire.tx_size(i) for i in range(3)] == [15, 13, 15]
    g = DriveGroup.from_config(t, cfg.bus)
    assert g.present("torque").tolist() == [True, False, True] * 2
    assert g.present("error_code").tolist() == [True, False, False] * 2
    g.set_mode(Mode.CSP)
    g.enable()
    assert g.all_in(State.OPERATION_ENABLED)
    q0 = g.q.copy()
    step = np.full(6, 0.05)
    ok = 0
    for k in range(300):
        g.command_position(q0 + step * min(1.0, k / 150))
        ok += g.cycle() == STATUS_OK
        t.wait_next_cycle()
    assert ok >= 280
    wait_for(
        lambda: (g.cycle(), bool(np.allclose(g.q - q0, step, atol=3e-3)))[1],
        10.0,
        "every joint at its step",
    )
    g.disable()


def test_a_fixed_tpdo_that_reads_back_different_is_refused_in_one_line(can_bus) -> None:
    cfg, channel, emu, masters = can_bus
    wrong = copy.deepcopy(CAN_TECHNOSOFT)
    wrong["tx_pdos"][0]["entries"] = wrong["tx_pdos"][0]["entries"][::-1]
    profiles = [profile(p) for p in CAN_MIXED]
    profiles[2] = profile(wrong)
    t = _master(cfg, channel, masters, profiles)
    with pytest.raises(CANopenError) as err:
        t.open()
    msg = str(err.value)
    assert "TPDO1 mapping 0x1A00 reads back as [0x6041:00/16, 0x6061:00/8]" in msg
    assert "expects [0x6061:00/8, 0x6041:00/16]" in msg and "\n" not in msg
    del emu
