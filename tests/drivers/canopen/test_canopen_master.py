"""The CANopen master against the emulated CANopen drives on python-can's virtual bus."""

from __future__ import annotations

import numpy as np
import pytest
from support.canopen import wait_for

from drivers.canopen.errors import IdentityMismatchError
from drivers.canopen.master import STATUS_HEARTBEAT_LOST
from drivers.cia402.drive_group import DriveFaultError, DriveGroup
from drivers.cia402.state_machine import Mode, State
from drivers.transport import STATUS_OK, STATUS_PARTIAL, SdoAbortError, backend_class
from hofto_hw.errors import ConfigError


def _group(rig, **kw):
    t = rig.master(**kw)
    t.open()
    g = DriveGroup.from_config(t, rig.cfg.bus)
    g.configure(rig.cfg.bus.drives)
    return t, g


def _cycle_until(t, g, cond, what, limit=2000):
    for _ in range(limit):
        t.wait_next_cycle()
        g.cycle()
        if cond():
            return
    raise AssertionError(f"no {what} within {limit} cycles")


def test_backend_is_registered() -> None:
    from drivers.canopen.master import CANopenTransport

    assert backend_class("canopen") is CANopenTransport


def test_open_checks_identity_maps_pdos_and_enables_six_axes(rig) -> None:
    t, g = _group(rig)
    for i in range(6):  # mapping read back from each node
        assert t.read_value(i, 0x1A00, 0, "u8") == 3
        assert t.read_value(i, 0x1A01, 2, "u32") == 0x60780010
        assert t.read_value(i, 0x1800, 1, "u32") == 0x180 + i + 1
        assert t.read_value(i, 0x1017, 0, "u16") == 50
    assert rig.emu.status()["nmt"] == [5] * 6
    g.set_mode(Mode.CSP)
    g.enable()
    assert g.all_in(State.OPERATION_ENABLED)
    assert rig.emu.status()["drive_state"] == [int(State.OPERATION_ENABLED)] * 6


def test_csp_move_is_followed_by_the_plant(rig) -> None:
    t, g = _group(rig)
    g.set_mode(Mode.CSP)
    g.enable()
    q0 = g.q.copy()
    target = q0 + np.array([0.1, -0.05, 0.05, 0.1, -0.1, 0.2])
    for k in range(1, 301):  # 1.5 s: a 0.3 s ramp, then the drives settle
        g.command_position(q0 + (target - q0) * min(1.0, k / 60))
        t.wait_next_cycle()
        g.cycle()
    plant_q = np.array(rig.emu.status()["q"])
    np.testing.assert_allclose(plant_q, target, atol=5e-3)
    np.testing.assert_allclose(g.q, plant_q, atol=5e-3)


def test_cst_torque_reaches_the_plant(rig) -> None:
    t, g = _group(rig)
    g.set_mode(Mode.CST)
    tau = np.array([5.0, -8.0, 3.0, 1.0, -1.0, 0.5])
    g.enable()
    g.command_torque(tau)
    for _ in range(3):  # applied at the next SYNC, measured in the TPDOs of the one after
        t.wait_next_cycle()
        g.cycle()
    applied = np.array(rig.emu.status()["tau_applied"])
    np.testing.assert_allclose(applied, tau, atol=0.02)
    np.testing.assert_allclose(g.tau, tau, atol=0.25)  # measured: 0.05 N·m noise, per-mille steps


def test_wrong_identity_names_node_expected_and_found(rig) -> None:
    rig.call(op="identity", node=2, product_code=0x00BAD000)
    t = rig.master()
    with pytest.raises(IdentityMismatchError) as e:
        t.open()
    msg = str(e.value)
    assert "node 3 (joint_3)" in msg and "product code 0x00BAD000" in msg
    assert "expected 0x00402001" in msg
    assert not t.is_open


def test_heartbeat_loss_is_a_fault_naming_the_node(rig) -> None:
    t, g = _group(rig)
    assert t.exchange() == STATUS_OK
    rig.call(op="silence", node=4, on=True)
    statuses: list[int] = []

    def lost() -> bool:
        t.wait_next_cycle()
        statuses.append(t.exchange())
        return statuses[-1] == STATUS_HEARTBEAT_LOST

    wait_for(lost, 10.0, "heartbeat loss")
    problems = " | ".join(t.problems())
    assert "node 5 (joint_5): heartbeat lost" in problems
    assert "node 1" not in problems


def test_emcy_becomes_a_drive_fault_with_its_code_in_words(rig) -> None:
    t, g = _group(rig)
    g.set_mode(Mode.CSP)
    g.enable()
    rig.call(op="emcy", node=1, code=0x2310)
    _cycle_until(t, g, g.any_fault, "fault")
    wait_for(lambda: bool(t.emergency_messages()), 5.0, "EMCY")
    assert "node 2 (joint_2): EMCY 0x2310 continuous over-current" in t.emergency_messages()[0]
    g.cycle()  # the EMCY's code reaches tx["error_code"] in the next exchange
    assert int(t.tx["error_code"][1]) == 0x2310
    with pytest.raises(
        DriveFaultError, match=r"axis 1 \(joint_2\).*0x2310 continuous over-current"
    ):
        g.enable()
    g.fault_reset()
    assert not g.any_fault()
    wait_for(lambda: t.emergency_messages()[-1].endswith("error reset (no error)"), 5.0, "reset")


def test_sdo_abort_is_decoded_naming_the_node(rig) -> None:
    t, g = _group(rig)
    rig.call(op="sdo_abort", node=3, index=0x6072, sub=0, code=0x08000022)
    with pytest.raises(SdoAbortError) as e:
        t.write_value(3, 0x6072, 0, "u16", 100)
    assert e.value.code == 0x08000022
    assert "joint_4, node 4" in str(e.value)
    assert "present device state" in str(e.value)
    with pytest.raises(SdoAbortError, match="0x06020000 object does not exist"):
        t.sdo_read(0, 0x2345, 0)


def test_missing_and_late_tpdos_give_partial_naming_the_node(rig) -> None:
    t, g = _group(rig, tpdo_deadline=0.02)
    _cycle_until(t, g, lambda: g.status == STATUS_OK, "a good cycle", 200)
    rig.call(op="tpdo", node=5, mode="drop", count=5)
    _cycle_until(t, g, lambda: "node 6 (joint_6)" in t.missing_nodes(), "node 6 missing", 200)
    assert g.status == STATUS_PARTIAL
    assert "node 6 (joint_6): TPDOs missing or late" in " | ".join(t.problems())
    _cycle_until(t, g, lambda: g.status == STATUS_OK, "recovery", 200)
    late_before = t.late_frames
    rig.call(op="tpdo", node=0, mode="late", count=5, delay=0.1)
    _cycle_until(t, g, lambda: "node 1 (joint_1)" in t.missing_nodes(), "node 1 late", 200)
    assert g.status == STATUS_PARTIAL
    _cycle_until(t, g, lambda: t.late_frames > late_before, "late frames counted", 400)


def test_bus_load_refused_at_open(rig) -> None:
    from drivers.canopen.master import CANopenTransport

    t = CANopenTransport(
        rig.channel, rig.cfg.bus.drives, 1 / 1000, can_interface="virtual", node_ids=None
    )
    with pytest.raises(
        ConfigError, match=r"bus load 318 % at 1000 Hz.*highest feasible rate is 220 Hz"
    ):
        t.open()


def test_missing_node_at_boot_is_named(rig) -> None:
    rig.call(op="silence", node=2, on=True)
    t = rig.master(boot_timeout=0.5)
    with pytest.raises(Exception, match=r"no boot-up message from node 3 \(joint_3\)"):
        t.open()


def test_nmt_stop_of_one_node_is_reported_by_its_heartbeat(rig) -> None:
    from drivers.canopen.master import STATUS_NOT_OPERATIONAL

    t, g = _group(rig)
    t.nmt("stop", 2)
    statuses: list[int] = []

    def stopped() -> bool:
        t.wait_next_cycle()
        statuses.append(t.exchange())
        return statuses[-1] == STATUS_NOT_OPERATIONAL

    wait_for(stopped, 10.0, "node 3 stopped")
    assert rig.emu.status()["nmt"][2] == 4
    assert "node 3 (joint_3): left operational, heartbeat reports stopped" in t.problems()
    t.nmt("start")
    wait_for(lambda: t.exchange() == STATUS_OK, 10.0, "all operational again")
    with pytest.raises(Exception, match="unknown NMT command 'sleep'"):
        t.nmt("sleep")


def test_from_config_takes_the_options_and_the_loop_cycle() -> None:
    from support.canopen import load_cfg

    from drivers.canopen.master import CANopenTransport

    cfg = load_cfg()
    t = CANopenTransport.from_config(
        cfg.bus, list(cfg.robot.joints), cycle_time=1.0 / cfg.loop.rate_hz
    )
    assert t.cycle_time == pytest.approx(0.005)
    assert (t.can_interface, t.channel) == ("udp_multicast", "239.74.163.2")
    assert t.node_ids == [1, 2, 3, 4, 5, 6]
    assert t.heartbeat_timeout == pytest.approx(0.15)
    assert t.tpdo_deadline == pytest.approx(0.004)
    assert t.load().load == pytest.approx(0.635, abs=0.001)


def _bus_health(cfg):
    from safety.bus_health import BusHealth
    from safety.stop import StopController

    fault_states = (int(State.FAULT_REACTION_ACTIVE), int(State.FAULT), int(State.UNKNOWN))
    health = BusHealth(6, cfg.safety.bus.lost_cycles, int(State.OPERATION_ENABLED), fault_states)
    return health, StopController.from_config(cfg.safety.categories)


def test_a_tpdo_stream_late_by_whole_cycles_is_never_fresh_and_a_bus_loss(rig) -> None:
    """Node 1 answers each SYNC 1.5 cycles late: every answer lands in the next cycle's
    window. Before, that read as fresh data one cycle old; now no cycle of the spell is ok,
    the loop's bus supervision latches a bus loss with the configured category, and the
    node's backlog (sent in order when the spell ends) makes the bus ok again."""
    from drivers.canopen.master import STATUS_TPDO_LATE
    from safety.stop import Fault
    from tests.support.reference_safety import bus_check

    cycle = 1.0 / rig.cfg.loop.rate_hz
    t, g = _group(rig, tpdo_deadline=0.8 * cycle, tpdo_resync=2.0)
    _cycle_until(t, g, lambda: g.status == STATUS_OK, "a good cycle", 400)
    health, stop = _bus_health(rig.cfg)
    spell = 60
    rig.call(op="tpdo", node=0, mode="late", count=spell, delay=1.5 * cycle)
    _cycle_until(t, g, lambda: g.status != STATUS_OK, "the first late cycle", 100)
    statuses = []
    for k in range(spell // 2):  # well inside the spell, wherever it started
        t.wait_next_cycle()
        g.cycle()
        stop.begin_tick(k)
        bus_check(health, stop, g.status, g.fresh, g.states, t.tx["error_code"], False)
        statuses.append(g.status)
    assert STATUS_OK not in statuses, statuses
    assert not g.fresh
    assert STATUS_TPDO_LATE in statuses, statuses
    assert stop.is_latched(Fault.BUS_LOSS)
    assert stop.category == rig.cfg.safety.categories.bus_loss
    if g.status == STATUS_TPDO_LATE:
        assert "node 1 (joint_1)" in t.missing_nodes()  # (others may be late on a loaded CI)
        assert "node 1 (joint_1): TPDOs missing or late" in " | ".join(t.problems())
    _cycle_until(t, g, lambda: g.status == STATUS_OK, "the backlog paid", 400)
    assert t.resyncs == 0  # the frames came, late and in order: nothing written off


def test_a_lost_tpdo_is_written_off_after_tpdo_resync(rig) -> None:
    """Three SYNCs left unanswered (as frames lost on the way) read as a lag until
    ``tpdo_resync`` has passed; then the backlog is written off and the node is on time."""
    cycle = 1.0 / rig.cfg.loop.rate_hz
    t, g = _group(rig, tpdo_deadline=0.8 * cycle, tpdo_resync=20 * cycle)
    _cycle_until(t, g, lambda: g.status == STATUS_OK, "a good cycle", 400)
    rig.call(op="tpdo", node=3, mode="drop", count=3)
    _cycle_until(t, g, lambda: "node 4 (joint_4)" in t.missing_nodes(), "node 4 missing", 200)
    _cycle_until(t, g, lambda: g.status == STATUS_OK, "written off", 400)
    assert t.resyncs >= 1
