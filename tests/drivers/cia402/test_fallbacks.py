"""Profile fallbacks computed, not just reported: ``torque: current`` (joint torque = current x
kt x gear, in SI), ``velocity: position_derivative`` (filtered position difference over the
sample interval, no allocation), and a drive without a torque offset named at start-up."""

from __future__ import annotations

import copy
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from support.profiles import BUILTINLIKE, INOVANCE, MIXED, SPARSE, write_mixed_config

from drivers.cia402.drive_group import DriveGroup
from drivers.cia402.fallbacks import VELOCITY_CUTOFF_HZ, DerivedSignals
from drivers.cia402.pdo import new_tx
from drivers.cia402.state_machine import Mode, State
from drivers.transport import STATUS_OK
from hofto_hw.config.loader import load_config
from hofto_hw.runtime.build import build_sim_bus

#: the built-in layout without 0x606C: the velocity is the position's derivative
NO_VELOCITY = copy.deepcopy(BUILTINLIKE)
NO_VELOCITY["name"] = "test_no_velocity"
NO_VELOCITY["tx_pdos"][0]["entries"] = [
    e for e in NO_VELOCITY["tx_pdos"][0]["entries"] if e["index"] != 0x606C
]
NO_VELOCITY["fallbacks"] = {"velocity": "position_derivative"}
NO_VELOCITY["objects"] = {"absent": ["velocity"]}

#: SPARSE with the torque reported as unavailable instead of computed from the current
SPARSE_NO_TAU = copy.deepcopy(SPARSE)
SPARSE_NO_TAU["name"] = "test_sparse_no_tau"
SPARSE_NO_TAU["fallbacks"]["torque"] = "unavailable"


def _enabled_group(tmp_path: Path, profiles):
    cfg = load_config(write_mixed_config(tmp_path, profiles))
    bus = build_sim_bus(cfg, external=False)
    g = DriveGroup.from_config(bus, cfg.bus)  # before open, as the run builds it
    bus.open()
    g.configure(cfg.bus.drives)
    g.set_mode(Mode.CSP)
    g.enable()
    assert g.all_in(State.OPERATION_ENABLED)
    return cfg, bus, g


def test_torque_from_current_is_current_times_kt_times_gear_in_si(tmp_path: Path) -> None:
    # the sparse drive (no 0x6077, 0x6078 mapped) on the shoulder, which holds the arm
    _cfg, bus, g = _enabled_group(tmp_path, [INOVANCE, SPARSE, *MIXED[2:]])
    assert bus.torque_from_current.tolist() == [False, True, False, True, False, False]
    q0 = g.q.copy()
    for _ in range(200):
        g.command_position(q0)
        assert g.cycle() == STATUS_OK
    true_tau = bus.plant.tau_meas
    assert abs(true_tau[1]) > 5.0  # gravity on the shoulder: a torque worth measuring
    d = bus.drives.scaling
    lsb = d.rated_current[1] * 1e-6 * d.torque_constant[1] * d.gear_ratio[1]  # one 0.1 % step
    assert abs(g.tau[1] - true_tau[1]) <= 0.6 * lsb
    np.testing.assert_allclose(g.tau[1], g.current[1] * 0.2286 * 100.0, rtol=1e-12)
    assert any("axis 1" in u and "computed from the current" in u for u in g.unavailable())


def test_torque_unavailable_reads_zero_and_says_so(tmp_path: Path) -> None:
    _cfg, bus, g = _enabled_group(tmp_path, [INOVANCE, SPARSE_NO_TAU, *MIXED[2:]])
    assert not bus.torque_from_current[1]
    for _ in range(50):
        g.command_position(g.q.copy())
        g.cycle()
    assert g.tau[1] == 0.0 and abs(bus.plant.tau_meas[1]) > 5.0
    assert any("axis 1" in u and "no measured torque" in u for u in g.unavailable())


def test_velocity_from_the_position_difference_tracks_the_true_velocity(tmp_path: Path) -> None:
    _cfg, bus, g = _enabled_group(tmp_path, [NO_VELOCITY, *MIXED[1:]])
    assert not g.present("velocity")[0] and g.present("velocity")[5]
    q0 = g.q.copy()
    rate = 0.4  # rad/s on joint 0, a ramp of 0.5 s
    errors = []
    for k in range(700):
        target = q0.copy()
        target[0] += rate * min(k, 500) * 1e-3
        g.command_position(target)
        assert g.cycle() == STATUS_OK
        if 300 <= k < 480:  # steady motion
            errors.append(g.qd[0] - bus.plant.qd[0])
    errors_a = np.array(errors)
    assert abs(np.mean(g.qd[0:1])) < 0.02  # at rest again after the ramp
    assert np.max(np.abs(errors_a)) < 0.02 * rate  # within 2 % of the speed while moving
    assert any("axis 0" in u and "position difference" in u for u in g.unavailable())


def test_derived_velocity_filters_wraps_holds_and_allocates_nothing() -> None:
    tx = new_tx(2)
    d = DerivedSignals(tx, np.array([False, False]), np.array([True, False]), 0.001)
    tx["velocity"][1] = 1234  # reported by its drive: left alone
    tx["position"][0] = 2**31 - 500  # about to wrap
    d.apply(0.0)
    assert tx["velocity"][0] == 0  # no difference yet
    pos = tx["position"][0:1]
    for _ in range(40):  # +1000 counts per 1 ms sample: 1e6 counts/s, through the wrap
        np.add(pos, 1000, out=pos)  # int32: wraps as the encoder's counter does
        d.apply(0.0)
    assert tx["position"][0] < 0  # it did wrap
    assert abs(int(tx["velocity"][0]) - 1_000_000) <= 1
    assert tx["velocity"][1] == 1234
    before = int(tx["velocity"][0])
    tx["position"][0] += 50_000  # no new sample (sample_dt < 0): held, no jump
    d.apply(-1.0)
    assert int(tx["velocity"][0]) == before
    # a step of the rate: first-order response with the documented cut-off
    d2 = DerivedSignals(tx, np.array([False, False]), np.array([True, False]), 0.001)
    tx["position"][0] = 0
    d2.apply(0.0)
    tx["position"][0] = 1000
    d2.apply(0.001)
    alpha = 1.0 - np.exp(-2.0 * np.pi * VELOCITY_CUTOFF_HZ * 0.001)
    assert abs(int(tx["velocity"][0]) - round(alpha * 1e6)) <= 1
    for _ in range(50):
        d2.apply(0.001)  # warm
    tracemalloc.start()
    for _ in range(200):
        tx["position"][0] += 7
        d2.apply(0.001)
    _size, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert peak < 1024  # nothing but interpreter scalars


def test_a_drive_without_torque_offset_is_named_at_start_up(tmp_path: Path) -> None:
    # axis 0 (Elmo-like): target_torque_in_cst; axis 3 (sparse): unavailable
    _cfg, _bus, g = _enabled_group(tmp_path, MIXED)
    notes = g.feedforward_notes(Mode.CSP)
    assert len(notes) == 2
    assert notes[0].startswith("axis 0 (") and "only through the target torque in CST" in notes[0]
    assert "in CSP this joint runs without it" in notes[0]
    assert notes[1].startswith("axis 3 (") and "no gravity feed-forward" in notes[1]
    in_cst = g.feedforward_notes(Mode.CST)
    assert len(in_cst) == 1 and in_cst[0].startswith("axis 3 (")


@pytest.mark.root
def test_velocity_from_position_over_the_ethercat_emulator_with_dc(tmp_path: Path) -> None:
    """The real master on the emulated bus, DC on (the sample interval from the reference
    clock): a drive without 0x606C reads the velocity of the true arm while it moves."""
    from support.rootnet import emulator, sim_ethercat_args, veth_pair

    from drivers.cia402.profiles import profiles_for
    from drivers.ethercat.master import EtherCATTransport

    config = write_mixed_config(tmp_path, [NO_VELOCITY, *MIXED[1:]])
    cfg = load_config(config)
    with (
        veth_pair("fm", "fs") as (master, slave),
        emulator(sim_ethercat_args(slave, config), tmp_path, timeout=30.0) as emu,
    ):
        t = EtherCATTransport(
            master, cfg.bus.drives, cfg.cycle_time, list(cfg.robot.joints),
            dc_sync=True, receive_timeout=0.02, pdo_watchdog=2.0,
            profiles=profiles_for(cfg.bus.drives, "ethercat"),
        )  # fmt: skip
        try:
            t.open()
            g = DriveGroup.from_config(t, cfg.bus)
            g.set_mode(Mode.CSP)
            g.enable()
            assert g.all_in(State.OPERATION_ENABLED)
            q0 = g.q.copy()
            rate = 0.3  # rad/s on joint 0 for 1 s
            pairs = []
            for k in range(1300):
                target = q0.copy()
                target[0] += rate * min(k, 1000) * cfg.cycle_time
                g.command_position(target)
                g.cycle()
                t.wait_next_cycle()
                if k in (500, 650, 800):  # steady motion: the master's figure and the arm's
                    pairs.append((float(g.qd[0]), float(emu.call(op="status")["qd"][0])))
            for measured, true in pairs:
                assert abs(measured - true) < 0.05 * rate, pairs
            assert abs(g.qd[0]) < 0.02 * rate  # at rest after the ramp
            g.disable()
        finally:
            t.close()
