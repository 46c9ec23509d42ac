"""The pysoem master against emulated EtherCAT drives on a veth pair (root).

The emulator runs in a child process (`hofto-hw sim-ethercat`); the real SOEM master scans
it, maps the PDOs by SDO, brings it to OP and runs the CiA-402 drive layer over it.
"""

from __future__ import annotations

import socket
import time

import numpy as np
import pytest

from drivers.cia402.codes import describe_error_code, describe_sdo_abort
from drivers.cia402.drive_group import DriveGroup
from drivers.cia402.state_machine import Mode, State
from drivers.ethercat.errors import (
    EtherCATError,
    IdentityMismatchError,
    SlaveLostError,
    StateChangeError,
)
from drivers.ethercat.master import EtherCATTransport
from drivers.transport import (
    STATUS_BUS_ERROR,
    STATUS_NO_RESPONSE,
    STATUS_OK,
    STATUS_WKC_MISMATCH,
    SdoAbortError,
)

pytestmark = pytest.mark.root


def _transport(bus, drives=None, **kw) -> EtherCATTransport:
    """A master for the emulated bus. Tests pause cycling between steps (control requests,
    checks), so the SM watchdog is 2 s unless a test sets it: with the slaves' 100 ms a
    descheduled test process would trip it (a real loop never pauses)."""
    cfg = bus.cfg
    kw.setdefault("pdo_watchdog", 2.0)
    return EtherCATTransport(
        bus.master_iface,
        drives if drives is not None else cfg.bus.drives,
        cfg.cycle_time,
        list(cfg.robot.joints),
        receive_timeout=0.02,  # generous: the test machine is shared
        **kw,
    )


def _cycle_until(t: EtherCATTransport, done, what: str, timeout: float = 20.0) -> list[int]:
    """Keep the bus cycling until ``done()`` (a state, not a time); fail after ``timeout``."""
    out = []
    deadline = time.monotonic() + timeout
    while not done():
        assert time.monotonic() < deadline, f"{what} not reached within {timeout} s"
        out.append(t.exchange())
        t.wait_next_cycle()
    return out


def _enabled_group(t: EtherCATTransport, cfg, mode: Mode, configure: bool = False) -> DriveGroup:
    """Open ``t`` and enable its drives in ``mode`` (CiA-402 drive layer over EtherCAT)."""
    t.open()
    g = DriveGroup.from_config(t, cfg.bus)
    if configure:
        g.configure(cfg.bus.drives)
    g.set_mode(mode)
    g.enable()
    return g


def _cycles(t: EtherCATTransport, n: int) -> list[int]:
    out = []
    for _ in range(n):
        out.append(t.exchange())
        t.wait_next_cycle()
    return out


def test_soem_finds_six_drives_and_brings_them_to_op(emulated_bus) -> None:
    t = _transport(emulated_bus)
    try:
        t.open()
        assert len(t.slaves) == 6
        assert t.expected_wkc == 18  # 3 per slave: outputs written (2) + inputs read (1)
        assert t.check_bus() == []
        assert all(s.name == "hofto-sim CiA-402 servo" for s in t.slaves)
        assert [s.get_watchdog("processdata") for s in t.slaves] == [2000.0] * 6
        status = emulated_bus.call(op="status")
        assert status["al_state"] == [0x08] * 6
        # the master wrote the mapping and assignment by SDO in PRE-OP -> SAFE-OP
        assert t.read_value(0, 0x1C12, 1, "u16") == 0x1600
        assert t.read_value(5, 0x1A00, 0, "u8") == 8
        assert set(_cycles(t, 20)) == {STATUS_OK}
    finally:
        t.close()


def test_wrong_product_code_names_slave_expected_and_found(emulated_bus) -> None:
    drives = [d.model_copy(deep=True) for d in emulated_bus.cfg.bus.drives]
    drives[2].identity.product_code = 0x00402099
    t = _transport(emulated_bus, drives)
    with pytest.raises(IdentityMismatchError) as err:
        t.open()
    msg = str(err.value)
    assert "slave 3" in msg and "product code" in msg
    assert "0x00402099" in msg and "0x00402001" in msg
    assert (err.value.slave, err.value.expected, err.value.found) == (3, 0x00402099, 0x00402001)
    assert t.master is None  # interface closed again


def test_csp_move_on_every_joint_is_followed_by_the_plant(emulated_bus) -> None:
    t = _transport(emulated_bus)
    try:
        g = _enabled_group(t, emulated_bus.cfg, Mode.CSP, configure=True)
        assert g.all_in(State.OPERATION_ENABLED)
        q0 = g.q.copy()
        plant0 = np.array(emulated_bus.call(op="status")["q"])
        step = np.array([0.05, -0.04, 0.03, 0.06, -0.05, 0.08])
        statuses = []
        for k in range(500):
            g.command_position(q0 + step * min(1.0, k / 300))
            statuses.append(g.cycle())
            t.wait_next_cycle()
        # a busy shared machine may delay a frame past the timeout now and then
        assert statuses.count(STATUS_OK) >= 490
        plant = np.array(emulated_bus.call(op="status")["q"])
        np.testing.assert_allclose(plant - plant0, step, atol=3e-3)
        np.testing.assert_allclose(g.q - q0, step, atol=3e-3)
    finally:
        t.close()


def test_cst_torque_reaches_the_plant(emulated_bus) -> None:
    t = _transport(emulated_bus)
    try:
        g = _enabled_group(t, emulated_bus.cfg, Mode.CST)
        tau = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 1.5])
        g.command_torque(tau)
        for _ in range(10):
            assert g.cycle() == STATUS_OK
            t.wait_next_cycle()
        applied = np.array(emulated_bus.call(op="status")["tau_applied"])
        assert applied[5] == pytest.approx(1.5, abs=0.05)
        assert g.tau[5] == pytest.approx(1.5, abs=0.05)  # the drive reports it back
    finally:
        t.close()


def test_dropped_and_damaged_frames_are_detected_in_the_same_cycle(emulated_bus) -> None:
    t = _transport(emulated_bus)
    try:
        t.open()
        assert set(_cycles(t, 5)) == {STATUS_OK}
        good = t.tx.copy()
        emulated_bus.call(op="drop", count=1)
        assert t.exchange() == STATUS_NO_RESPONSE
        assert t.tx.tobytes() == good.tobytes(), "tx keeps the last good values"
        assert t.exchange() == STATUS_OK
        emulated_bus.call(op="corrupt", count=1, slave=3)
        assert t.exchange() == STATUS_WKC_MISMATCH
        assert t.last_wkc == 9  # slaves 0-2 still counted 3 each
        assert t.exchange() == STATUS_OK
        assert (t.lost_frames, t.wkc_errors) == (1, 1)
    finally:
        t.close()


def test_drive_group_flags_stale_data_after_a_lost_or_damaged_frame(emulated_bus) -> None:
    cfg = emulated_bus.cfg
    t = _transport(emulated_bus)
    try:
        t.open()
        g = DriveGroup.from_config(t, cfg.bus)
        assert g.cycle() == STATUS_OK and g.fresh
        emulated_bus.call(op="drop", count=1)
        assert g.cycle() == STATUS_NO_RESPONSE
        assert not g.fresh and g.stale_cycles == 1
        emulated_bus.call(op="corrupt", count=1, slave=2)
        assert g.cycle() == STATUS_WKC_MISMATCH
        assert not g.fresh and g.stale_cycles == 2
        assert g.cycle() == STATUS_OK
        assert g.fresh and g.stale_cycles == 0
    finally:
        t.close()


def test_silent_slave_is_reported_and_stops_the_bus(emulated_bus) -> None:
    t = _transport(emulated_bus)
    try:
        t.open()
        emulated_bus.call(op="silence", slave=3, on=True)
        assert t.exchange() == STATUS_WKC_MISMATCH
        problems = t.check_bus()
        assert len(problems) == 1
        assert "slave 4" in problems[0] and "does not answer" in problems[0]
        with pytest.raises(SlaveLostError, match="slave 4"):
            t.recover_slaves()
        assert t.exchange() == STATUS_BUS_ERROR
    finally:
        t.close()


def test_lost_slave_is_recovered_when_it_returns(emulated_bus) -> None:
    t = _transport(emulated_bus, recover=True, pdo_watchdog=0.1)
    try:
        t.open()
        emulated_bus.call(op="silence", slave=1, on=True)
        # past the 100 ms SM watchdog the silent slave drops to SAFE-OP + ERROR
        _cycle_until(
            t,
            lambda: emulated_bus.call(op="status")["al_state"][1] == 0x14,
            "SM watchdog of the silent slave",
        )
        assert t.exchange() == STATUS_WKC_MISMATCH
        emulated_bus.call(op="silence", slave=1, on=False)
        status = emulated_bus.call(op="status")
        assert status["al_state"][1] == 0x14 and status["al_status_code"][1] == 0x001B
        notes = t.recover_slaves()
        assert any("slave 2" in n and "0x001B" in n for n in notes), notes
        assert t.check_bus() == []
        assert set(_cycles(t, 10)) == {STATUS_OK}
    finally:
        t.close()


def test_restarted_slave_is_readdressed_and_remapped(emulated_bus) -> None:
    t = _transport(emulated_bus, recover=True)
    try:
        t.open()
        emulated_bus.call(op="restart", slave=4)
        assert t.exchange() == STATUS_WKC_MISMATCH
        assert any("slave 5" in p and "does not answer" in p for p in t.check_bus())
        notes = t.recover_slaves()
        assert any("slave 5" in n and "reconfigured" in n for n in notes), notes
        assert t.check_bus() == []
        assert emulated_bus.call(op="status")["al_state"] == [0x08] * 6
        assert set(_cycles(t, 10)) == {STATUS_OK}
    finally:
        t.close()


def test_drive_fault_is_surfaced_with_its_code(emulated_bus) -> None:
    t = _transport(emulated_bus)
    try:
        g = _enabled_group(t, emulated_bus.cfg, Mode.CSP)
        emulated_bus.call(op="drive_fault", slave=1, code=0x2310)
        for _ in range(5):
            g.hold()
            g.cycle()
            t.wait_next_cycle()
        assert int(t.tx["error_code"][1]) == 0x2310
        faults = t.drive_faults()
        assert len(faults) == 1
        assert "slave 2" in faults[0] and describe_error_code(0x2310) in faults[0]
        assert any("0x2310" in m for m in t.emergency_messages())
    finally:
        t.close()


def test_drive_fault_with_an_aborted_0x603f_read_is_still_reported(emulated_bus) -> None:
    """The fault-read path: an SDO abort on 0x603F is reported, not raised (defect 4)."""
    t = _transport(emulated_bus)
    try:
        g = _enabled_group(t, emulated_bus.cfg, Mode.CSP)
        emulated_bus.call(op="sdo_abort", slave=2, index=0x603F, sub=0, code=0x06060000)
        emulated_bus.call(op="drive_fault", slave=2, code=0x2310)
        for _ in range(5):
            g.hold()
            g.cycle()
            t.wait_next_cycle()
        assert int(t.tx["error_code"][2]) == 0x2310
        faults = t.drive_faults()  # raised SdoAbortError before the fix
        assert len(faults) == 1
        assert "slave 3" in faults[0] and "unreadable" in faults[0]
        assert "0x06060000" in faults[0]
        # the drive layer falls back to the PDO copy of 0x603F
        assert g.error_code(2) == 0x2310
        assert any(describe_error_code(0x2310) in m for m in g.fault_messages())
    finally:
        t.close()


def test_sdo_abort_is_surfaced_with_its_meaning(emulated_bus) -> None:
    t = _transport(emulated_bus)
    try:
        t.open()
        emulated_bus.call(op="sdo_abort", slave=0, index=0x6072, sub=-1, code=0x08000021)
        with pytest.raises(SdoAbortError) as err:
            t.sdo_read(0, 0x6072, 0)
        assert err.value.code == 0x08000021
        assert "0x6072" in str(err.value) and describe_sdo_abort(0x08000021) in str(err.value)
        # a real refusal: PDO assignment cannot change in OP
        with pytest.raises(SdoAbortError) as err:
            t.sdo_write(4, 0x1C12, 0, b"\x00")
        assert err.value.code == 0x08000022 and err.value.axis == 4
    finally:
        t.close()


def test_a_late_sdo_answer_is_not_taken_for_the_next_read_of_another_subindex(
    emulated_bus,
) -> None:
    """The emulated drive answers 0x1018:01 only after the master has given up (held until
    its next mailbox request). SOEM matches an answer by index, not subindex: without the
    resync the read of 0x1018:02 that follows would return 0x1018:01's value."""
    ident = emulated_bus.cfg.bus.drives[2].identity
    t = _transport(emulated_bus, mailbox_retries=0, sdo_timeout=0.2)
    try:
        t.open()
        emulated_bus.call(op="sdo_late", slave=2, index=0x1018, sub=1, count=1)
        with pytest.raises(EtherCATError, match=r"slave 3 .*SDO read 0x1018:01 failed after 1"):
            t.sdo_read(2, 0x1018, 1)
        assert t.read_value(2, 0x1018, 2, "u32") == ident.product_code
        assert t.read_value(2, 0x1018, 1, "u32") == ident.vendor_id
        assert t.mailbox_resynced == 1
    finally:
        t.close()


def test_a_retry_of_a_late_sdo_leaves_no_answer_behind_for_the_next_read(emulated_bus) -> None:
    """Two late answers in a row: the retry of 0x1018:01 would take the first (the right
    value) and leave its own for the read of 0x1018:02 (the 'product code 0x00000DEC'
    start-up refusal of issue 25, there with a stalled emulator)."""
    ident = emulated_bus.cfg.bus.drives[2].identity
    t = _transport(emulated_bus, sdo_timeout=0.2)
    try:
        t.open()
        emulated_bus.call(op="sdo_late", slave=2, index=0x1018, sub=1, count=2)
        assert t.read_value(2, 0x1018, 1, "u32") == ident.vendor_id
        assert t.read_value(2, 0x1018, 2, "u32") == ident.product_code
        assert t.mailbox_resynced == 2
    finally:
        t.close()


def test_refused_state_change_is_surfaced_with_its_al_status_code(emulated_bus) -> None:
    emulated_bus.call(op="refuse_state", slave=4, state=0x08, code=0x001A)
    t = _transport(emulated_bus, state_timeout=1.0)
    with pytest.raises(StateChangeError) as err:
        t.open()
    msg = str(err.value)
    assert "OP" in msg and "slave 5" in msg and "SAFE-OP + ERROR" in msg
    assert "0x001A" in msg and "synchronization error" in msg
    assert err.value.problems == {5: (0x14, 0x001A)}


def test_al_error_in_op_is_reported_by_check_bus(emulated_bus) -> None:
    t = _transport(emulated_bus)
    try:
        t.open()
        emulated_bus.call(op="al_error", slave=0, code=0x001B)
        problems = t.check_bus()
        assert len(problems) == 1 and "slave 1" in problems[0]
        assert "SAFE-OP + ERROR" in problems[0] and "0x001B" in problems[0]
    finally:
        t.close()


def test_dc_sync0_start_up(emulated_bus) -> None:
    t = _transport(emulated_bus, dc_sync=True)
    try:
        t.open()
        assert t.check_bus() == []
        assert set(_cycles(t, 10)) == {STATUS_OK}
    finally:
        t.close()


def test_dc_time_gives_the_sample_interval_not_the_master_wake_up(emulated_bus) -> None:
    """With DC the transport reports how far the drives' samples moved: the emulated arm
    moves one cycle per exchange, so a master that oversleeps still gets one cycle."""
    t = _transport(emulated_bus, dc_sync=True)
    try:
        t.open()
        assert set(_cycles(t, 5)) == {STATUS_OK}
        assert t.sample_dt == pytest.approx(t.cycle_time, abs=1e-12)
        time.sleep(10 * t.cycle_time)  # a stall of the master
        assert t.exchange() == STATUS_OK
        assert t.sample_dt == pytest.approx(t.cycle_time, abs=1e-12)
    finally:
        t.close()


def test_dc_a_lost_frame_brings_no_sample_and_the_next_spans_the_gap(emulated_bus) -> None:
    t = _transport(emulated_bus, dc_sync=True)
    try:
        t.open()
        assert set(_cycles(t, 5)) == {STATUS_OK}
        emulated_bus.call(op="drop", count=1)
        assert t.exchange() != STATUS_OK
        assert t.sample_dt == -1.0
        t.wait_next_cycle()
        assert t.exchange() == STATUS_OK
        # the dropped frame did not reach the drives: their samples moved one cycle
        assert t.sample_dt == pytest.approx(t.cycle_time, abs=1e-12)
    finally:
        t.close()


def test_without_dc_the_sample_interval_is_unknown(emulated_bus) -> None:
    t = _transport(emulated_bus)
    try:
        t.open()
        assert set(_cycles(t, 5)) == {STATUS_OK}
        assert t.sample_dt == 0.0
    finally:
        t.close()


def test_scapy_decodes_the_live_process_data_frame(emulated_bus) -> None:
    """Capture the cyclic frame on the master's interface and decode it independently."""
    scapy_all = pytest.importorskip("scapy.all", reason="scapy (dev extra) not installed")
    ecat = pytest.importorskip("scapy.contrib.ethercat")
    scapy_all.conf.max_list_count = 4096  # the LRW carries 216 data bytes (default limit 100)
    t = _transport(emulated_bus)
    t.open()
    # created after start-up so that its queue holds only the frames of this test
    sniff = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(0x88A4))
    try:
        sniff.bind((emulated_bus.master_iface, 0x88A4))
        sniff.setblocking(False)
        assert t.exchange() == STATUS_OK
        time.sleep(0.05)
        replies = []
        while True:
            try:
                data = sniff.recv(2048)
            except BlockingIOError:
                break
            if data[12:14] == b"\x88\xa4" and data[6] & 0x02:  # answered by the slaves
                replies.append(scapy_all.Ether(data))

        lrw = [p[ecat.EtherCatLRW] for p in replies if p.haslayer(ecat.EtherCatLRW)]
        assert lrw, "no process-data reply captured"
        frame = lrw[-1]
        assert frame.wkc == t.expected_wkc
        data = bytes(frame.data)
        # outputs of 6 slaves (15 bytes each) then their inputs (21 bytes each)
        assert data[6 * 15 :] == t.tx.tobytes()
    finally:
        sniff.close()
        t.close()
