"""Register space, AL state machine, SyncManager and FMMU behaviour of one emulated ESC."""

from __future__ import annotations

import struct

from esc_helpers import make_desc, make_od, request_state, setup_mailbox, sm_block, to_safeop_ready

from drivers.cia402 import pdo
from drivers.sim.esc import registers as r
from drivers.sim.esc.esc import Esc


def _read(esc: Esc, addr: int, n: int) -> bytes:
    buf = bytearray(n)
    assert esc.read(addr, buf, 0, n)
    return bytes(buf)


def test_station_address_is_writable_and_information_registers_are_not(esc: Esc) -> None:
    esc.write(r.STATION_ADDRESS, struct.pack("<H", 0x1003))
    assert esc.station_address == 0x1003
    before = _read(esc, r.TYPE, 8)
    esc.write(r.TYPE, bytes(8))
    assert _read(esc, r.TYPE, 8) == before
    assert _read(esc, r.FEATURES, 2)[0] & 0x04  # DC supported


def test_whole_sm_block_writes_keep_status_and_pdi_bytes(mailbox) -> None:
    esc = mailbox.esc
    # a reply waits in the read mailbox: SM1 status says "full"
    mailbox.send(struct.pack("<HBHB", 2 << 12, 0x40, 0x1000, 0) + bytes(4))
    status_before = _read(esc, r.SM_BASE + 8 + r.SM_STATUS_OFFSET, 1)[0]
    assert status_before & r.SM_STATUS_MAILBOX_FULL
    d = esc.desc
    esc.write(
        r.SM_BASE,
        sm_block(d.mbx_out_offset, d.mbx_out_size, 0x26)
        + sm_block(d.mbx_in_offset, d.mbx_in_size, 0x22),
    )
    assert _read(esc, r.SM_BASE + 8 + r.SM_STATUS_OFFSET, 1)[0] == status_before


def test_preop_needs_the_mailbox_configuration(esc: Esc) -> None:
    request_state(esc, r.STATE_PREOP)
    assert esc.al_state == r.STATE_INIT | r.AL_ERROR_FLAG
    assert esc.al_status_code == 0x0016
    setup_mailbox(esc)
    request_state(esc, r.STATE_PREOP)  # error not acknowledged: ignored
    assert esc.al_state == r.STATE_INIT | r.AL_ERROR_FLAG
    request_state(esc, r.STATE_PREOP | r.AL_ACK_FLAG)
    assert esc.al_state == r.STATE_PREOP
    assert esc.al_status_code == 0


def test_invalid_and_unknown_state_requests(esc: Esc) -> None:
    request_state(esc, r.STATE_OP)
    assert (esc.al_state, esc.al_status_code) == (r.STATE_INIT | r.AL_ERROR_FLAG, 0x0011)
    request_state(esc, 0x05 | r.AL_ACK_FLAG)
    assert (esc.al_state, esc.al_status_code) == (r.STATE_INIT | r.AL_ERROR_FLAG, 0x0012)


def test_safeop_and_op_with_the_default_mapping_then_down_to_init(esc: Esc) -> None:
    to_safeop_ready(esc)
    request_state(esc, r.STATE_SAFEOP)
    assert esc.al_state == r.STATE_SAFEOP, hex(esc.al_status_code)
    request_state(esc, r.STATE_OP)
    assert esc.al_state == r.STATE_OP
    request_state(esc, r.STATE_INIT)
    assert esc.al_state == r.STATE_INIT


def test_wrong_sm2_length_is_an_invalid_output_configuration(esc: Esc) -> None:
    to_safeop_ready(esc)
    esc.write(r.SM_BASE + 16, sm_block(esc.desc.outputs_offset, pdo.RXPDO_SIZE - 1, 0x64))
    request_state(esc, r.STATE_SAFEOP)
    assert esc.al_state == r.STATE_PREOP | r.AL_ERROR_FLAG
    assert esc.al_status_code == 0x001D


def test_refused_state_injection(esc: Esc) -> None:
    to_safeop_ready(esc)
    esc.refuse[r.STATE_SAFEOP] = 0x0026
    request_state(esc, r.STATE_SAFEOP)
    assert (esc.al_state, esc.al_status_code) == (r.STATE_PREOP | r.AL_ERROR_FLAG, 0x0026)


def test_sync0_cycle_below_125_us_is_refused(esc: Esc) -> None:
    to_safeop_ready(esc)
    esc.write(r.DC_SYNC0_CYCLE, struct.pack("<I", 50_000))
    esc.write(r.DC_ACTIVATION, b"\x03")
    request_state(esc, r.STATE_SAFEOP)
    assert esc.al_status_code == 0x0035


def _fmmu(log: int, length: int, phys: int, ftype: int) -> bytes:
    return struct.pack("<IHBBHBBBxxx", log, length, 0, 7, phys, 0, ftype, 1)


def test_lrw_through_fmmus_counts_3_and_moves_data_both_ways(esc: Esc) -> None:
    to_safeop_ready(esc)
    request_state(esc, r.STATE_SAFEOP)
    d = esc.desc
    esc.write(r.FMMU_BASE, _fmmu(0, 15, d.outputs_offset, 2) + _fmmu(15, 21, d.inputs_offset, 1))
    esc.mem[d.inputs_offset : d.inputs_offset + 21] = bytes(range(1, 22))
    frame = bytearray(b"\xaa" * 15 + bytes(21))
    assert esc.logical(12, 0, frame, 0, 36) == 3
    assert bytes(frame[15:]) == bytes(range(1, 22))
    assert esc.mem[d.outputs_offset : d.outputs_offset + 15] == b"\xaa" * 15
    assert esc.outputs_fresh
    # LRD only reads (+1), LWR only writes (+1)
    assert esc.logical(10, 0, bytearray(36), 0, 36) == 1
    assert esc.logical(11, 0, bytearray(36), 0, 36) == 1
    # a window that misses every FMMU counts nothing
    assert esc.logical(12, 100, bytearray(8), 0, 8) == 0


def test_process_data_is_not_served_below_safeop(esc: Esc) -> None:
    to_safeop_ready(esc)  # PRE-OP: SM2/SM3 deactivated by the slave
    d = esc.desc
    esc.write(r.FMMU_BASE, _fmmu(0, 15, d.outputs_offset, 2) + _fmmu(15, 21, d.inputs_offset, 1))
    assert esc.logical(12, 0, bytearray(36), 0, 36) == 0


def test_sm_watchdog_drops_op_to_safeop_with_0x001b() -> None:
    now = [0]
    esc = Esc(make_desc(), make_od(), clock=lambda: now[0])
    to_safeop_ready(esc)
    request_state(esc, r.STATE_SAFEOP)
    request_state(esc, r.STATE_OP)
    esc.check_watchdog(50_000_000)
    assert esc.al_state == r.STATE_OP
    esc.check_watchdog(150_000_000)  # 100 ms default
    assert esc.al_state == r.STATE_SAFEOP | r.AL_ERROR_FLAG
    assert esc.al_status_code == 0x001B


def test_dc_latch_and_system_time_offset() -> None:
    now = [1_000_000]
    esc = Esc(make_desc(), None, clock=lambda: now[0])
    esc.write(r.DC_RECEIVE_TIME_PORT0, bytes(4))
    assert struct.unpack("<Q", _read(esc, r.DC_RECEIVE_TIME_PU, 8))[0] == 1_000_000
    esc.write(r.DC_SYSTEM_TIME_OFFSET, struct.pack("<q", 5_000))
    now[0] = 2_000_000
    assert struct.unpack("<Q", _read(esc, r.DC_SYSTEM_TIME, 8))[0] == 2_005_000


def test_boot_is_entered_from_init_and_left_to_init_only(esc: Esc) -> None:
    setup_mailbox(esc)
    request_state(esc, r.STATE_BOOT)
    assert esc.al_state == r.STATE_BOOT
    request_state(esc, r.STATE_PREOP)
    assert (esc.al_state, esc.al_status_code) == (r.STATE_BOOT | r.AL_ERROR_FLAG, 0x0011)
    request_state(esc, r.STATE_INIT | r.AL_ACK_FLAG)
    assert esc.al_state == r.STATE_INIT


def test_application_error_drops_op_to_safeop(esc: Esc) -> None:
    to_safeop_ready(esc)
    request_state(esc, r.STATE_SAFEOP)
    request_state(esc, r.STATE_OP)
    esc.raise_al_error(0x001A)
    assert (esc.al_state, esc.al_status_code) == (r.STATE_SAFEOP | r.AL_ERROR_FLAG, 0x001A)
    request_state(esc, r.STATE_OP)  # not acknowledged: ignored
    assert esc.al_state == r.STATE_SAFEOP | r.AL_ERROR_FLAG
    request_state(esc, r.STATE_OP | r.AL_ACK_FLAG)
    assert esc.al_state == r.STATE_OP
