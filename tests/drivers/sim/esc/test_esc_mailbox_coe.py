"""Mailbox SyncManager rules and the CoE SDO server (expedited, normal, segmented, CA, abort)."""

from __future__ import annotations

import struct

import pytest
from esc_helpers import Mailbox, make_desc, make_od, request_state, setup_mailbox, to_safeop_ready

from drivers.cia402 import pdo
from drivers.sim.esc import registers as r
from drivers.sim.esc.esc import Esc

SDO_REQ, SDO_RES = 2, 3


def _coe(reply: bytes) -> tuple[int, int, int, int, bytes]:
    """(service, command, index, sub, data after the 8-byte SDO header) of a reply."""
    service = struct.unpack_from("<H", reply, 6)[0] >> 12
    command = reply[8]
    index, sub = struct.unpack_from("<HB", reply, 9)
    return service, command, index, sub, reply[12:]


def test_read_mailbox_rules(mailbox: Mailbox) -> None:
    esc = mailbox.esc
    assert mailbox.receive() is None, "an empty read mailbox must not be read (no WKC)"
    mailbox.send(struct.pack("<HBHB", 2 << 12, 0x40, 0x1000, 0) + bytes(4))
    assert mailbox.receive() is not None
    assert mailbox.receive() is None, "reading the last byte empties the read mailbox"
    # a partial read (not covering the last byte) leaves it full
    mailbox.send(struct.pack("<HBHB", 2 << 12, 0x40, 0x1000, 0) + bytes(4))
    buf = bytearray(8)
    assert esc.read(esc.desc.mbx_in_offset, buf, 0, 8)
    assert esc.mem[r.SM_BASE + 8 + r.SM_STATUS_OFFSET] & r.SM_STATUS_MAILBOX_FULL


def test_repeat_request_resends_the_last_reply(mailbox: Mailbox) -> None:
    esc = mailbox.esc
    first = mailbox.sdo(0x40, 0x1018, 2)
    assert mailbox.receive() is None
    act = r.SM_BASE + 8 + r.SM_ACTIVATE_OFFSET
    esc.write(act, bytes([esc.mem[act] ^ r.SM_ACTIVATE_REPEAT]))
    assert esc.mem[r.SM_BASE + 8 + r.SM_PDI_CONTROL_OFFSET] & r.SM_PDI_REPEAT_ACK
    assert mailbox.receive() == first


def test_expedited_upload_and_download(mailbox: Mailbox) -> None:
    service, command, index, sub, data = _coe(mailbox.sdo(0x40, 0x1018, 2))
    assert (service, index, sub) == (SDO_RES, 0x1018, 2)
    assert command & 0x03 == 0x03  # expedited, size indicated
    size = 4 - ((command >> 2) & 3)
    assert struct.unpack("<I", data[:size])[0] == 0x00402001
    reply = mailbox.sdo(0x2B, 0x6072, 0, struct.pack("<HH", 777, 0))  # 2-byte download
    assert _coe(reply)[:2] == (SDO_RES, 0x60)
    service, command, *_rest, data = _coe(mailbox.sdo(0x40, 0x6072, 0))
    assert struct.unpack("<H", data[:2])[0] == 777


def test_normal_upload_of_a_string(mailbox: Mailbox) -> None:
    esc = Esc(make_desc(), make_od())
    setup_mailbox(esc)
    request_state(esc, r.STATE_PREOP)
    m = Mailbox(esc)
    _s, command, _i, _sub, data = _coe(m.sdo(0x40, 0x100A, 0))
    assert command & 0x03 == 0x01  # normal (not expedited), size indicated
    size = struct.unpack_from("<I", data)[0]
    assert data[4 : 4 + size] == b"hofto-sim 1"


def test_segmented_upload_with_a_small_mailbox() -> None:
    esc = Esc(make_desc(mbx_out_size=32, mbx_in_size=32), make_od())
    setup_mailbox(esc)
    request_state(esc, r.STATE_PREOP)
    m = Mailbox(esc)
    expected = esc.od.read(0x1008, 0)
    assert len(expected) > 60
    reply = m.sdo(0x40, 0x1008, 0)
    length = struct.unpack_from("<H", reply)[0]
    total = struct.unpack_from("<I", reply, 12)[0]
    got = bytearray(reply[16 : 6 + length])
    toggle = 0
    for _ in range(20):
        assert m.send(struct.pack("<HB", 2 << 12, 0x60 | toggle) + bytes(7))
        seg = m.receive()
        assert seg is not None
        seg_len = struct.unpack_from("<H", seg)[0]
        cmd = seg[8]
        assert cmd & 0x10 == toggle
        chunk = seg[9 : 6 + seg_len]
        if seg_len == 10:
            chunk = chunk[: 7 - ((cmd >> 1) & 7)]
        got += chunk
        toggle ^= 0x10
        if cmd & 0x01:
            break
    assert total == len(expected)
    assert bytes(got) == expected


def test_wrong_toggle_aborts_the_segmented_upload() -> None:
    esc = Esc(make_desc(mbx_out_size=32, mbx_in_size=32), make_od())
    setup_mailbox(esc)
    request_state(esc, r.STATE_PREOP)
    m = Mailbox(esc)
    m.sdo(0x40, 0x1008, 0)
    reply = m.sdo(0x60 | 0x10, 0, 0, bytes(4))  # first segment must have toggle 0
    service, command, index, _sub, data = _coe(reply)
    assert (service, command, index) == (SDO_REQ, 0x80, 0x1008)
    assert struct.unpack_from("<I", data)[0] == 0x05030000


def test_complete_access_upload_of_assignment_and_mapping(mailbox: Mailbox) -> None:
    _s, command, _i, _sub, data = _coe(mailbox.sdo(0x50, pdo.RXPDO_ASSIGN_INDEX, 0))
    assert command & 0x10
    size = struct.unpack_from("<I", data)[0]
    assert data[4 : 4 + size] == bytes([1, 0]) + struct.pack("<H", pdo.RXPDO_INDEX)
    _s, _c, _i, _sub, data = _coe(mailbox.sdo(0x50, pdo.TXPDO_INDEX, 0))
    size = struct.unpack_from("<I", data)[0]
    values = struct.unpack_from(f"<{len(pdo.TXPDO_MAPPING)}I", data, 6)
    assert size == 2 + 4 * len(pdo.TXPDO_MAPPING)
    assert list(values) == [pdo.mapping_value(e) for e in pdo.TXPDO_MAPPING]


def test_segmented_complete_access_download_remaps_the_rxpdo() -> None:
    esc = Esc(make_desc(mbx_out_size=32, mbx_in_size=32), make_od())
    setup_mailbox(esc)
    request_state(esc, r.STATE_PREOP)
    m = Mailbox(esc)
    entries = pdo.RXPDO_MAPPING[:3]  # controlword, mode, target position
    blob = bytes([len(entries), 0]) + b"".join(
        struct.pack("<I", pdo.mapping_value(e)) for e in entries
    )
    first = 32 - 16  # data room of the initiate request
    payload = struct.pack("<HBHBI", 2 << 12, 0x31, pdo.RXPDO_INDEX, 0, len(blob)) + blob[:first]
    assert m.send(payload)
    assert _coe(m.receive())[:2] == (SDO_RES, 0x60)
    rest, toggle = blob[first:], 0
    while rest:
        chunk, rest = rest[:23], rest[23:]
        last = 0x01 if not rest else 0
        if len(chunk) < 7:
            cmd = toggle | last | ((7 - len(chunk)) << 1)
            chunk = chunk.ljust(7, b"\x00")
        else:
            cmd = toggle | last
        assert m.send(struct.pack("<HB", 2 << 12, cmd) + chunk)
        reply = m.receive()
        assert reply[8] == 0x20 | toggle, reply.hex()
        toggle ^= 0x10
    assert esc.od.mapping(pdo.RXPDO_INDEX) == list(entries)


def test_abort_is_service_2_command_0x80_with_the_code(mailbox: Mailbox) -> None:
    service, command, index, sub, data = _coe(mailbox.sdo(0x40, 0x2345, 7))
    assert (service, command, index, sub) == (SDO_REQ, 0x80, 0x2345, 7)
    assert struct.unpack_from("<I", data)[0] == 0x06020000


def test_injected_abort_code(mailbox: Mailbox) -> None:
    mailbox.esc.coe.forced_aborts[(0x6072, -1)] = 0x08000021
    _s, command, *_r, data = _coe(mailbox.sdo(0x40, 0x6072, 0))
    assert command == 0x80
    assert struct.unpack_from("<I", data)[0] == 0x08000021


@pytest.mark.parametrize("index", [pdo.RXPDO_ASSIGN_INDEX, pdo.RXPDO_INDEX])
def test_pdo_objects_are_locked_in_safeop(index: int) -> None:
    esc = Esc(make_desc(), make_od())
    to_safeop_ready(esc)
    request_state(esc, r.STATE_SAFEOP)
    assert esc.al_state == r.STATE_SAFEOP
    m = Mailbox(esc)
    _s, command, *_r, data = _coe(m.sdo(0x2F, index, 0, bytes(4)))
    assert command == 0x80
    assert struct.unpack_from("<I", data)[0] == 0x08000022


def test_mapping_without_controlword_refuses_safeop_with_0x001d(mailbox: Mailbox) -> None:
    esc = mailbox.esc
    entries = [e for e in pdo.RXPDO_MAPPING if e.field != "controlword"]
    mailbox.sdo(0x2F, pdo.RXPDO_INDEX, 0, bytes(4))
    for k, e in enumerate(entries):
        reply = mailbox.sdo(0x23, pdo.RXPDO_INDEX, k + 1, struct.pack("<I", pdo.mapping_value(e)))
        assert _coe(reply)[1] == 0x60
    mailbox.sdo(0x2F, pdo.RXPDO_INDEX, 0, bytes([len(entries), 0, 0, 0]))
    size = sum(e.bit_length for e in entries) // 8
    to_safeop_ready(esc)
    esc.write(r.SM_BASE + 16, struct.pack("<HHBBBB", esc.desc.outputs_offset, size, 0x64, 0, 1, 0))
    request_state(esc, r.STATE_SAFEOP)
    assert esc.al_state == r.STATE_PREOP | r.AL_ERROR_FLAG
    assert esc.al_status_code == 0x001D


def test_emergency_frame_layout(mailbox: Mailbox) -> None:
    esc = mailbox.esc
    esc.queue_mailbox(esc.coe.emergency(0x2310, 0x03, b"\x01\x02"))
    frame = mailbox.receive()
    assert frame is not None
    assert frame[5] & 0x0F == 0x03
    service, code, reg = struct.unpack_from("<HHB", frame, 6)
    assert (service >> 12, code, reg) == (1, 0x2310, 0x03)
    assert frame[11:16] == b"\x01\x02\x00\x00\x00"


def test_unsupported_mailbox_protocol_gets_a_mailbox_error(mailbox: Mailbox) -> None:
    esc = mailbox.esc
    frame = struct.pack("<HHBB", 4, 0, 0, 0x14) + bytes(4)  # EoE (type 4)
    esc.write(esc.desc.mbx_out_offset, frame.ljust(esc.desc.mbx_out_size, b"\x00"))
    reply = mailbox.receive()
    assert reply[5] & 0x0F == 0x00
    assert struct.unpack_from("<HH", reply, 6) == (1, 0x0002)


def test_a_late_answer_comes_with_the_masters_next_request_before_its_own(
    mailbox: Mailbox,
) -> None:
    """``late``: the answer to 0x1018:01 is held (the master times out on it) and goes out
    when the master's next request arrives, before that request's own answer, in order."""
    esc = mailbox.esc
    esc.late[(0x1018, 1)] = 1
    mailbox.send(struct.pack("<HBHB", 2 << 12, 0x40, 0x1018, 1) + bytes(4))
    assert mailbox.receive() is None  # held: nothing to read however often asked
    assert mailbox.receive() is None
    mailbox.send(struct.pack("<HBHB", 2 << 12, 0x40, 0x1018, 2) + bytes(4))
    late = mailbox.receive()
    assert late is not None and _coe(late)[2:4] == (0x1018, 1)
    assert struct.unpack("<I", _coe(late)[4][:4])[0] == esc.od.get(0x1018, 1)
    own = mailbox.receive()
    assert own is not None and _coe(own)[2:4] == (0x1018, 2)
    assert mailbox.receive() is None
    # one answer only: the next request of 0x1018:01 is answered at once
    assert esc.late[(0x1018, 1)] == 0
    assert _coe(mailbox.sdo(0x40, 0x1018, 1))[2:4] == (0x1018, 1)
