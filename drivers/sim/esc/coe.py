"""CoE (CANopen over EtherCAT) mailbox server of an emulated slave: SDO and emergency.

Implements the SDO server side of ETG.1000.6 5.6.2: upload and download, expedited,
normal and segmented, single sub-index and complete access, abort (sent as CoE service 2,
"SDO request", with command 0x80, the form masters such as SOEM decode), plus emergency
messages (service 1) and the mailbox error reply for protocols other than CoE.

Mailbox frames are ``bytes`` including the 6-byte mailbox header:
``length u16 (bytes after the header), address u16, channel/priority u8, type|cnt<<4 u8``.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Protocol

from drivers.cia402 import codes
from drivers.sim.object_dictionary import SdoAbort

MBX_HEADER = 6
MBX_TYPE_ERROR = 0x00
MBX_TYPE_COE = 0x03

COE_EMERGENCY = 1
COE_SDO_REQUEST = 2
COE_SDO_RESPONSE = 3
COE_SDO_INFO = 8

MBX_ERR_SYNTAX = 0x0001
MBX_ERR_UNSUPPORTED_PROTOCOL = 0x0002
MBX_ERR_INVALID_SIZE = 0x0008

ABORT_TOGGLE = codes.ABORT_TOGGLE
ABORT_COMMAND = 0x05040001
ABORT_LENGTH = codes.ABORT_LENGTH
ABORT_UNSUPPORTED = codes.ABORT_UNSUPPORTED_ACCESS


class ObjectAccess(Protocol):
    """An object dictionary as the SDO server sees it: raw little-endian bytes.

    Both methods raise :class:`drivers.sim.object_dictionary.SdoAbort` with the CiA 301 code.
    """

    def read(self, index: int, subindex: int) -> bytes:
        """Value of ``index:subindex``."""
        ...

    def write(self, index: int, subindex: int, data: bytes) -> None:
        """Store ``data`` at ``index:subindex``."""
        ...


def mailbox(payload: bytes, mbx_type: int, counter: int) -> bytes:
    """Prepend a mailbox header (address 0, priority 0) to ``payload``."""
    header = struct.pack("<HHBB", len(payload), 0, 0, (mbx_type & 0x0F) | ((counter & 7) << 4))
    return header + payload


def _sdo(service: int, command: int, index: int, sub: int, data: bytes = b"") -> bytes:
    return struct.pack("<HBHB", service << 12, command, index, sub) + data


def abort_payload(index: int, sub: int, code: int) -> bytes:
    """CoE payload of an SDO abort (service 2, command 0x80)."""
    return _sdo(COE_SDO_REQUEST, 0x80, index, sub, struct.pack("<I", code))


def emergency_payload(error_code: int, error_register: int, data: bytes = b"") -> bytes:
    """CoE payload of an emergency: error code u16, error register u8, 5 bytes of data."""
    data = (data + bytes(5))[:5]
    return struct.pack("<HHB", COE_EMERGENCY << 12, error_code, error_register) + data


def read_complete(objects: ObjectAccess, index: int, sub: int) -> bytes:
    """Complete-access read: sub 0 as one byte padded to 16 bits (when ``sub == 0``)
    followed by sub-indices 1..n; a simple variable is returned as it is."""
    first = objects.read(index, 0)
    count = first[0] if len(first) == 1 else 0
    if count == 0 or not _has_sub(objects, index, 1):
        return first
    parts = [bytes([count, 0])] if sub == 0 else []
    for s in range(1, count + 1):
        parts.append(objects.read(index, s))
    return b"".join(parts)


def _has_sub(objects: ObjectAccess, index: int, sub: int) -> bool:
    try:
        objects.read(index, sub)
    except SdoAbort:
        return False
    return True


def write_complete(objects: ObjectAccess, index: int, sub: int, data: bytes) -> None:
    """Complete-access write: the inverse of :func:`read_complete`.

    Entry sizes are taken from the current values; sub 0 is written first as 0 and last
    with the new count, the order CiA 301 asks for when remapping PDOs.
    """
    pos = 0
    if sub == 0:
        if len(data) < 2:
            raise SdoAbort(ABORT_LENGTH, index, 0)
        count = data[0]
        pos = 2
    else:
        count = objects.read(index, 0)[0]
    objects.write(index, 0, b"\x00")
    for s in range(1, count + 1):
        size = len(objects.read(index, s))
        chunk = data[pos : pos + size]
        if len(chunk) != size:
            raise SdoAbort(ABORT_LENGTH, index, s)
        objects.write(index, s, chunk)
        pos += size
    if pos != len(data):
        raise SdoAbort(ABORT_LENGTH, index, sub)
    objects.write(index, 0, bytes([count]))


@dataclass
class _Transfer:
    """A segmented transfer in progress."""

    upload: bool
    index: int
    sub: int
    complete: bool
    data: bytearray
    total: int
    toggle: int = 0


class CoeServer:
    """SDO server for one slave; :meth:`handle` maps a request mailbox to reply mailboxes."""

    def __init__(self, objects: ObjectAccess, mbx_out_size: int, mbx_in_size: int) -> None:
        self.objects = objects
        self.mbx_out_size = mbx_out_size
        self.mbx_in_size = mbx_in_size
        self._transfer: _Transfer | None = None
        self._counter = 0
        #: sub-index -> forced abort code, for fault injection: ``(index, sub) -> code``;
        #: ``sub = -1`` matches every sub-index of the object.
        self.forced_aborts: dict[tuple[int, int], int] = {}

    def _next_counter(self) -> int:
        self._counter = self._counter % 7 + 1
        return self._counter

    def _reply(self, payload: bytes, mbx_type: int = MBX_TYPE_COE) -> bytes:
        return mailbox(payload, mbx_type, self._next_counter())

    def emergency(self, error_code: int, error_register: int, data: bytes = b"") -> bytes:
        """Mailbox frame of an emergency message."""
        return self._reply(emergency_payload(error_code, error_register, data))

    def mailbox_error(self, detail: int) -> bytes:
        """Mailbox error reply (type 0, service 1) with ``detail`` (ETG.1000.4 table 29)."""
        return self._reply(struct.pack("<HH", 1, detail), MBX_TYPE_ERROR)

    def handle(self, frame: bytes) -> bytes | None:
        """Answer one mailbox frame written by the master; ``None`` means no reply."""
        if len(frame) < MBX_HEADER:
            return self.mailbox_error(MBX_ERR_INVALID_SIZE)
        length, _addr, _prio, type_cnt = struct.unpack_from("<HHBB", frame)
        payload = frame[MBX_HEADER : MBX_HEADER + length]
        if len(payload) < length or length < 2:
            return self.mailbox_error(MBX_ERR_INVALID_SIZE)
        if type_cnt & 0x0F != MBX_TYPE_COE:
            return self.mailbox_error(MBX_ERR_UNSUPPORTED_PROTOCOL)
        service = struct.unpack_from("<H", payload)[0] >> 12
        if service != COE_SDO_REQUEST:
            if service == COE_SDO_INFO:
                # SDO information is not implemented: answer with an SDO info error
                # (opcode 7) so the master does not wait for a timeout.
                return self._reply(
                    struct.pack("<HBBHI", COE_SDO_INFO << 12, 0x07, 0, 0, ABORT_UNSUPPORTED)
                )
            return self.mailbox_error(MBX_ERR_UNSUPPORTED_PROTOCOL)
        if len(payload) < 3:
            return self.mailbox_error(MBX_ERR_INVALID_SIZE)
        command = payload[2]
        index, sub = (0, 0)
        if len(payload) >= 6:
            index, sub = struct.unpack_from("<HB", payload, 3)
        active = self._transfer
        try:
            return self._reply(self._sdo(command, index, sub, payload))
        except SdoAbort as abort:
            if active is not None and command >> 5 in (0, 3):  # a segment: name the object
                index, sub = active.index, active.sub
            self._transfer = None
            return self._reply(abort_payload(index, sub, abort.code))

    # ------------------------------------------------------------------- SDO commands

    def _check_forced(self, index: int, sub: int) -> None:
        code = self.forced_aborts.get((index, sub), self.forced_aborts.get((index, -1)))
        if code is not None:
            raise SdoAbort(code, index, sub)

    def _sdo(self, command: int, index: int, sub: int, payload: bytes) -> bytes:
        ccs = command >> 5
        if ccs == 2:  # initiate upload
            self._transfer = None
            self._check_forced(index, sub)
            return self._upload(index, sub, bool(command & 0x10))
        if ccs == 1:  # initiate download
            self._transfer = None
            self._check_forced(index, sub)
            return self._download(command, index, sub, payload)
        if ccs == 3:  # upload segment
            return self._upload_segment(command)
        if ccs == 0:  # download segment
            return self._download_segment(command, payload)
        if command == 0x80:  # abort from the master: drop any transfer
            self._transfer = None
            raise SdoAbort(ABORT_COMMAND, index, sub)
        raise SdoAbort(ABORT_COMMAND, index, sub)

    def _upload(self, index: int, sub: int, complete: bool) -> bytes:
        data = (
            read_complete(self.objects, index, sub) if complete else self.objects.read(index, sub)
        )
        ca = 0x10 if complete else 0
        if len(data) <= 4 and not complete:
            cmd = 0x43 | ((4 - len(data)) << 2)
            return _sdo(COE_SDO_RESPONSE, cmd, index, sub, data.ljust(4, b"\x00"))
        room = self.mbx_in_size - MBX_HEADER - 10
        first = data[:room]
        if len(data) > room:
            self._transfer = _Transfer(
                True, index, sub, complete, bytearray(data[room:]), len(data)
            )
        return _sdo(COE_SDO_RESPONSE, 0x41 | ca, index, sub, struct.pack("<I", len(data)) + first)

    def _upload_segment(self, command: int) -> bytes:
        t = self._transfer
        if t is None or not t.upload:
            raise SdoAbort(ABORT_COMMAND, 0, 0)
        toggle = command & 0x10
        if toggle != t.toggle:
            raise SdoAbort(ABORT_TOGGLE, t.index, t.sub)
        room = self.mbx_in_size - MBX_HEADER - 3
        chunk = bytes(t.data[:room])
        del t.data[:room]
        last = not t.data
        cmd = toggle | (0x01 if last else 0)
        if len(chunk) < 7:
            cmd |= (7 - len(chunk)) << 1
            chunk = chunk.ljust(7, b"\x00")
        t.toggle ^= 0x10
        if last:
            self._transfer = None
        return struct.pack("<HB", COE_SDO_RESPONSE << 12, cmd) + chunk

    def _download(self, command: int, index: int, sub: int, payload: bytes) -> bytes:
        complete = bool(command & 0x10)
        if command & 0x02:  # expedited
            size = 4 - ((command >> 2) & 0x03) if command & 0x01 else 4
            self._store(index, sub, complete, bytes(payload[6 : 6 + size]))
            return _sdo(COE_SDO_RESPONSE, 0x60, index, sub, bytes(4))
        if len(payload) < 10:
            raise SdoAbort(ABORT_LENGTH, index, sub)
        total = struct.unpack_from("<I", payload, 6)[0]
        data = bytes(payload[10:])
        if len(data) >= total:
            self._store(index, sub, complete, data[:total])
        else:
            self._transfer = _Transfer(False, index, sub, complete, bytearray(data), total)
        return _sdo(COE_SDO_RESPONSE, 0x60, index, sub, bytes(4))

    def _download_segment(self, command: int, payload: bytes) -> bytes:
        t = self._transfer
        if t is None or t.upload:
            raise SdoAbort(ABORT_COMMAND, 0, 0)
        toggle = command & 0x10
        if toggle != t.toggle:
            raise SdoAbort(ABORT_TOGGLE, t.index, t.sub)
        chunk = payload[3:]
        if len(payload) == 10:  # minimum-size segment: unused bytes are encoded
            chunk = chunk[: 7 - ((command >> 1) & 0x07)]
        t.data += chunk
        t.toggle ^= 0x10
        if command & 0x01:
            self._transfer = None
            if len(t.data) != t.total:
                raise SdoAbort(ABORT_LENGTH, t.index, t.sub)
            self._store(t.index, t.sub, t.complete, bytes(t.data))
        elif len(t.data) > t.total:
            raise SdoAbort(ABORT_LENGTH, t.index, t.sub)
        return struct.pack("<HB", COE_SDO_RESPONSE << 12, 0x20 | toggle) + bytes(7)

    def _store(self, index: int, sub: int, complete: bool, data: bytes) -> None:
        if complete:
            write_complete(self.objects, index, sub, data)
        else:
            self.objects.write(index, sub, data)
