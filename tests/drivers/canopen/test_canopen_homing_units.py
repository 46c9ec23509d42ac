"""Homing a drive whose profile states rpm and rpm/s (the Faulhaber profile with its units
set): 0x6099 and 0x609A are written in the drive's units, converted in drivers/ only, and
the emulated drive (which takes them in those units) homes on its index pulse."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from support.canopen import CONFIG, ROOT, unique_channel

from hofto_hw.config.drives import HomingConfig
from hofto_hw.config.loader import dump_yaml

AXIS = 4  # joint_5: no brake, little gravity


@pytest.fixture()
def rpm_bus(tmp_path: Path):
    """Six emulated nodes (virtual bus), joint_5 a Faulhaber in rpm; an open master,
    configured (0x608F checked against counts_per_rev)."""
    import can

    from drivers.canopen.master import CANopenTransport
    from drivers.cia402.drive_group import DriveGroup
    from drivers.sim.canopen_node import CanopenDrives
    from hofto_hw.config.loader import load_config
    from hofto_hw.runtime.build import build_emulated_drives

    prof = yaml.safe_load((ROOT / "configs" / "drives" / "faulhaber_mcbl300x.yaml").read_text())
    prof["units"].update(velocity="rpm", acceleration="rpm/s")
    prof_path = tmp_path / "faulhaber_mcbl300x.yaml"
    prof_path.write_text(yaml.safe_dump(prof, sort_keys=False))
    data = yaml.safe_load(CONFIG.read_text())
    data["robot"]["urdf"] = str((CONFIG.parent / data["robot"]["urdf"]).resolve())
    channel = unique_channel("homing")
    data["bus"].update(interface=channel)
    data["bus"]["canopen"].update(can_interface="virtual", tpdo_deadline=0.05, sdo_timeout=2.0)
    drive = data["bus"]["drives"][AXIS]
    drive["profile"] = str(prof_path)
    drive["identity"] = dict(prof["identity"])
    drive["identity"].pop("revision_min", None)
    drive["identity"].pop("revision_max", None)
    path = tmp_path / "rpm.yaml"
    path.write_text(dump_yaml(data, sort_keys=False))
    cfg = load_config(path)
    bus = can.Bus(interface="virtual", channel=channel)
    nodes = CanopenDrives(build_emulated_drives(cfg, external=False), bus).start()
    t = CANopenTransport.from_config(cfg.bus, list(cfg.robot.joints), cycle_time=cfg.cycle_time)
    try:
        t.open()
        group = DriveGroup.from_config(t, cfg.bus)
        group.configure(cfg.bus.drives)
        yield cfg, t, group, nodes
    finally:
        t.close()
        nodes.stop()
        bus.shutdown()


def test_homing_speeds_and_acceleration_go_to_the_drive_in_rpm(rpm_bus) -> None:
    from drivers.cia402.homing import home_axes, homing_plan
    from drivers.cia402.state_machine import Mode

    cfg, t, group, nodes = rpm_bus
    d = cfg.bus.drives[AXIS]
    group.cycle()
    group.set_mode(Mode.CSP)
    group.enable()
    # settle after the enable at the enable's position (holding the measured position would
    # carry on any motion the enable left: the arm at rest before homing)
    q_hold = group.q.copy()
    for _ in range(round(1.0 / t.cycle_time)):
        group.command_position(q_hold)
        t.wait_next_cycle()
        group.cycle()
    q0 = float(nodes.status()["q"][AXIS])
    pitch = 2.0 * math.pi / d.gear_ratio  # one motor turn
    index = q0 - 0.3 * pitch  # the next index pulse below the start
    assert nodes.control({"op": "index_phase", "node": AXIS, "phase": index})["ok"]
    # the emulated velocity loop lags a 50 mrad/s search by ~10 mrad: a slow search, and a
    # tolerance for where it stops (what is checked is where the drive says home is)
    homing = HomingConfig(method=33, speeds=(0.2, 0.02), acceleration=2.0, offset=0.1,
                          timeout=10.0, tolerance=0.02)  # fmt: skip
    plan = homing_plan(homing, group.scaling, AXIS, t.cycle_time, "joint_5",
                       group.drive_units(AXIS))  # fmt: skip
    rpm_per_rad_s = d.gear_ratio * 60.0 / (2.0 * math.pi)  # motor min^-1 per joint rad/s
    assert plan.speeds == (round(0.2 * rpm_per_rad_s), round(0.02 * rpm_per_rad_s))
    assert plan.acceleration == round(2.0 * rpm_per_rad_s)  # rpm/s
    assert group.drive_units(0) == (1.0, 1.0)  # the built-in drives take counts/s
    assert home_axes(group, [plan]) == ""
    assert [t.read_value(AXIS, 0x6099, s, "u32") for s in (1, 2)] == list(plan.speeds)
    assert t.read_value(AXIS, 0x609A, 0, "u32") == plan.acceleration
    # the drive latched the pulse: reported - offset = true - the pulse's position
    true_q = float(nodes.status()["q"][AXIS])
    assert float(group.q[AXIS]) - 0.1 == pytest.approx(true_q - index, abs=2e-4)
    # and went back to the mode it runs the loop's CSP in (profile velocity), not 8
    assert int(np.asarray(t.tx["mode_display"])[AXIS]) == int(Mode.PROFILE_VELOCITY)
    group.disable()
