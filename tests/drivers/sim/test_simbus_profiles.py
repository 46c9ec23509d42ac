"""The in-process simulated bus with six drive profiles: configured as a master configures
them (start-up SDOs, PDOs written and read back), the process data in each drive's own
layout, and the CiA-402 group over the mixed image."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
from support.profiles import INOVANCE, MIXED, SPARSE, write_mixed_config

from drivers.cia402.drive_group import DriveGroup
from drivers.cia402.state_machine import Mode, State
from drivers.transport import STATUS_OK, TransportError
from hofto_hw.config.loader import load_config
from hofto_hw.runtime.build import build_sim_bus


def _bus(tmp_path: Path, profiles=None):
    cfg = load_config(write_mixed_config(tmp_path, profiles))
    return cfg, build_sim_bus(cfg, external=False)


def test_mixed_profiles_run_the_group_in_their_own_layouts(tmp_path: Path) -> None:
    cfg, bus = _bus(tmp_path)
    bus.open()
    w = bus.wire
    assert not w.builtin
    assert [w.rx_size(i) for i in range(6)] == [14, 14, 15, 14, 15, 15]
    assert bus.startup_written == 3
    g = DriveGroup.from_config(bus, cfg.bus)
    g.configure(cfg.bus.drives)
    g.set_mode(Mode.CSP)
    g.enable()
    assert g.all_in(State.OPERATION_ENABLED)
    # axis 1 has no 0x6061 mapped: the group read it by SDO and keeps it
    assert int(g._tx_mode[1]) == Mode.CSP
    q0 = g.q.copy()
    for k in range(300):
        g.command_position(q0 + 0.05 * min(1.0, k / 150), tau_offset=np.full(6, 0.5))
        assert g.cycle() == STATUS_OK
    np.testing.assert_allclose(g.q - q0, 0.05, atol=2e-3)
    # what a drive does not map does not reach it; what it does not report reads 0
    drives = bus.drives
    assert drives.rx["torque_offset"][3] == 0 and drives.rx["torque_offset"][1] != 0
    # (axis 3 maps no torque: its canonical torque field carries its current, fallback
    # ``torque: current``; the error code it does not map reads 0)
    assert bus.tx["torque"][3] == bus.tx["current"][3] != 0
    assert bus.tx["error_code"][3] == 0
    assert g.present("torque").tolist() == [True, True, True, False, True, True]


def test_a_drive_whose_mapping_cannot_be_written_is_refused(tmp_path: Path) -> None:
    sparse = copy.deepcopy(SPARSE)
    profiles = [INOVANCE, sparse, *MIXED[2:]]
    cfg, bus = _bus(tmp_path, profiles)
    # the drive's own dictionary lacks an object the profile maps: its mapping write aborts
    bus.drives.ods[1].remove(0x60B8)
    with pytest.raises(TransportError) as err:
        bus.open()
    assert "0x1600" in str(err.value) and "\n" not in str(err.value)


def test_a_profile_path_relative_to_the_config_is_found_from_any_folder(
    tmp_path: Path, monkeypatch
) -> None:
    config = write_mixed_config(tmp_path)
    text = config.read_text().replace(str(tmp_path) + "/", "")
    assert "profile: test_elmo.yaml" in text
    config.write_text(text)
    monkeypatch.chdir("/")
    cfg = load_config(config)
    bus = build_sim_bus(cfg, external=False)
    bus.open()
    assert bus.wire.layouts[0].rx_pdos == (0x1605,)


def test_ip_and_pv_drives_on_the_in_process_bus(tmp_path: Path) -> None:
    """The shipped Technosoft (ip) and Faulhaber (pv) profiles on the sim bus: their CANopen
    start-up writes (transition PO) are written too (the interpolation period), the group in
    CSP selects modes 7 / 3, and a CSP step reaches both kinds of drive through the adapter."""
    import yaml

    root = Path(__file__).resolve().parents[3] / "configs" / "drives"
    ip = yaml.safe_load((root / "technosoft_ipos.yaml").read_text())
    pv = yaml.safe_load((root / "faulhaber_mcbl300x.yaml").read_text())
    cfg, bus = _bus(tmp_path, [ip, pv] * 3)
    bus.open()
    assert bus.startup_written == 3 * len(ip["startup"])
    drives = bus.drives
    assert drives.ip_period[::2].tolist() == [1] * 3  # 1 kHz: 1 x 1e-3 s
    g = DriveGroup.from_config(bus, cfg.bus)
    g.set_mode(Mode.CSP)
    assert drives.mode_display.tolist() == [7, 3] * 3
    g.enable()
    assert (bus.tx["statusword"][::2] & 0x1000).all()  # ip mode active
    q0 = g.q.copy()
    for k in range(1500):
        g.command_position(q0 + 0.05 * min(1.0, k / 400))
        assert g.cycle() == STATUS_OK
    np.testing.assert_allclose(g.q - q0, 0.05, atol=5e-3)
    assert (bus.rx["target_velocity"] == 0).all()  # the loop's record stayed CSP


def test_the_ip_pv_step_idles_when_no_axis_runs_ip_or_pv(tmp_path: Path) -> None:
    """Drives that could run ip / pv skip that step on a cycle where no axis does (every
    cycle of a CSP arm of them) and give the same bytes as running it: enabled in ip / pv,
    moved, disabled (idle), enabled again, against the same run with the step on every
    cycle."""
    import yaml

    root = Path(__file__).resolve().parents[3] / "configs" / "drives"
    ip = yaml.safe_load((root / "technosoft_ipos.yaml").read_text())
    pv = yaml.safe_load((root / "faulhaber_mcbl300x.yaml").read_text())

    def run(every_cycle: bool) -> tuple[list[bytes], int]:
        cfg, bus = _bus(tmp_path, [ip, pv] * 3)
        drives = bus.drives
        idle = drives._ip_pv_idle
        calls = [0]

        def spy() -> None:
            calls[0] += 1
            (drives._ip_pv if every_cycle else idle)()

        drives._ip_pv_idle = spy
        bus.open()
        g = DriveGroup.from_config(bus, cfg.bus)
        g.set_mode(Mode.CSP)
        out = []
        for _ in range(2):
            g.enable()
            q0 = g.q.copy()
            for k in range(300):
                g.command_position(q0 + 0.05 * min(1.0, k / 100))
                g.cycle()
                out.append(bus.tx.tobytes() + drives.plant.q_meas.tobytes())
            g.disable()
            for _ in range(20):
                g.cycle()
                out.append(bus.tx.tobytes() + drives.plant.q_meas.tobytes())
        return out, calls[0]

    idle, idle_cycles = run(every_cycle=False)
    full, _ = run(every_cycle=True)
    assert idle_cycles > 40  # the idle step ran (disabled, before enabling)
    assert idle == full
