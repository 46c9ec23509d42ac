"""Helpers for the emulated EtherCAT slave tests: slaves with a real CiA-402 dictionary."""

from __future__ import annotations

import struct

import numpy as np

from drivers.cia402 import pdo
from drivers.sim.esc import registers as r
from drivers.sim.esc.description import SlaveDescription
from drivers.sim.esc.esc import Esc
from drivers.sim.object_dictionary import DriveObjects, ObjectDictionary, cia402_dictionary

VENDOR, PRODUCT, REVISION = 0x00000DEC, 0x00402001, 0x00010002


def make_od(n: int = 1, axis: int = 0) -> ObjectDictionary:
    """The emulated drive's object dictionary (no plant needed)."""
    objs = DriveObjects(
        pdo.new_rx(n),
        pdo.new_tx(n),
        np.zeros(n, np.uint16),
        np.ones(n, np.uint32),
        np.zeros(n, np.uint32),
        np.zeros(n, np.uint16),
        np.zeros(n, np.int16),
        np.zeros(n, np.uint8),
    )
    return cia402_dictionary(
        axis,
        objs,
        vendor_id=VENDOR,
        product_code=PRODUCT,
        revision=REVISION,
        serial=7,
        device_name="a drive with a name long enough to need segments " * 2,
        counts_per_rev=131072,
        gear_motor_revs=100,
        gear_shaft_revs=1,
        rated_torque_mnm=640,
        rated_current_ma=2800,
    )


def make_desc(**kw: int) -> SlaveDescription:
    return SlaveDescription(vendor_id=VENDOR, product_code=PRODUCT, revision=REVISION, **kw)


def sm_block(start: int, length: int, control: int, enable: int = 1) -> bytes:
    """8-byte SyncManager register block as a master writes it (status/PDI bytes zero)."""
    return struct.pack("<HHBBBB", start, length, control, 0, enable, 0)


def setup_mailbox(esc: Esc) -> None:
    """Program SM0/SM1 from the description, like SOEM does in config_init."""
    d = esc.desc
    esc.write(
        r.SM_BASE,
        sm_block(d.mbx_out_offset, d.mbx_out_size, 0x26)
        + sm_block(d.mbx_in_offset, d.mbx_in_size, 0x22),
    )


def request_state(esc: Esc, state: int) -> None:
    esc.write(r.AL_CONTROL, bytes([state, 0]))


def to_safeop_ready(esc: Esc) -> None:
    """Mailbox SMs, PRE-OP, SM2/SM3 for the default mapping (not yet SAFE-OP)."""
    setup_mailbox(esc)
    request_state(esc, r.STATE_PREOP)
    d = esc.desc
    esc.write(r.SM_BASE + 16, sm_block(d.outputs_offset, pdo.RXPDO_SIZE, 0x64))
    esc.write(r.SM_BASE + 24, sm_block(d.inputs_offset, pdo.TXPDO_SIZE, 0x20))


class Mailbox:
    """Master side of one slave's mailbox, talking CoE frames through ESC accesses."""

    def __init__(self, esc: Esc) -> None:
        self.esc = esc
        self.counter = 0

    def send(self, payload: bytes) -> bool:
        d = self.esc.desc
        self.counter = self.counter % 7 + 1
        frame = struct.pack("<HHBB", len(payload), 0, 0, 0x03 | (self.counter << 4)) + payload
        return self.esc.write(d.mbx_out_offset, frame.ljust(d.mbx_out_size, b"\x00"))

    def receive(self) -> bytes | None:
        d = self.esc.desc
        buf = bytearray(d.mbx_in_size)
        if not self.esc.read(d.mbx_in_offset, buf, 0, d.mbx_in_size):
            return None
        length = struct.unpack_from("<H", buf)[0]
        return bytes(buf[: 6 + length])

    def sdo(self, command: int, index: int, sub: int, data: bytes = b"\x00" * 4) -> bytes:
        payload = struct.pack("<HBHB", 2 << 12, command, index, sub) + data
        assert self.send(payload)
        reply = self.receive()
        assert reply is not None
        return reply
