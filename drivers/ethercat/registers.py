"""ESC register access beside SOEM: one datagram in one EtherCAT frame of our own.

pysoem 1.1.13 has no public register write (only the private ``CdefSlave._fpwr``), and
SOEM's ``dc_sync`` always writes 0x00 to the cyclic unit control register (0x0980,
AssignActivate's low byte). :class:`RegisterPort` writes and reads such a register itself:
an Ethernet frame (Ethertype 0x88A4) carrying one datagram, sent and received on an
AF_PACKET socket of its own bound to the master's interface.

Why this does not confuse SOEM (OpenEtherCATsociety/SOEM oshw/linux/nicdrv.c, and the
copy pysoem builds, bnjmnp/pysoem oshw/linux/nicdrv.c, the same receive logic):
- it is used only between SOEM calls, on the master's own thread (every SOEM register or
  mailbox call waits for its own frame before it returns; pysoem releases the GIL while it
  waits, so the port must never be used from another thread while SOEM runs), so SOEM has
  no frame in flight;
- SOEM's socket receives our returning frame (both sockets are bound to the EtherCAT
  Ethertype on the interface). ``ecx_inframe`` files a frame under its datagram index only
  when the index is below EC_MAXBUF (16) and a frame of that index is in flight; anything
  else it drops ("strange things happend") and keeps waiting for its own. Our frames carry
  an index of 0xA0 and up, which SOEM's ``ecx_getindex`` (0..15) never gives.
- outgoing frames (ours, SOEM's): Linux hands a frame going out only to packet sockets
  bound to every protocol (ETH_P_ALL), so neither socket sees the other's; a frame of
  packet type PACKET_OUTGOING is skipped all the same. Of the frames coming in, only the
  answer to ours counts: the same index, command and register address (SOEM's returning
  frames have indices below 16).

A datagram that no slave performed (working counter 0) or no answer within ``timeout``
(retried ``attempts`` times with a fresh index: a write is idempotent) raises EtherCATError
naming the interface, the slave and the register.
"""

from __future__ import annotations

import select
import socket
import struct
import time
from typing import Any

from drivers.ethercat.errors import EtherCATError

ETHERTYPE_ECAT = 0x88A4
#: datagram commands (ETG.1000.4)
APRD, FPRD, FPWR = 0x01, 0x04, 0x05
#: ESC registers
STATION_ADDRESS = 0x0010
CYCLIC_UNIT_CONTROL = 0x0980  # AssignActivate's low byte (sync/latch units: ECAT or PDI)
#: SOEM's frame buffers (EC_MAXBUF): its datagram indices are below this
SOEM_MAX_INDEX = 16
_FIRST_INDEX = 0xA0  # ours: far above SOEM's, one per attempt

_ETH = struct.Struct("!6s6sH")
_ECAT = struct.Struct("<H")
_DATAGRAM = struct.Struct("<BBHHHH")
_BROADCAST = b"\xff" * 6
_SOURCE = b"\x01\x01\x01\x01\x01\x01"  # the same as SOEM's primary source MAC
_MIN_FRAME = 60  # Ethernet minimum without FCS: short frames are padded
_PACKET_OUTGOING = 4  # linux/if_packet.h: sll_pkttype of a frame going out


def build_frame(command: int, index: int, adp: int, ado: int, data: bytes) -> bytes:
    """An EtherCAT frame with one datagram (no more following, working counter 0)."""
    dlen = len(data)
    body = _DATAGRAM.pack(command, index, adp & 0xFFFF, ado, dlen & 0x07FF, 0) + data + b"\0\0"
    frame = _ETH.pack(_BROADCAST, _SOURCE, ETHERTYPE_ECAT) + _ECAT.pack(0x1000 | len(body))
    frame += body
    return frame + bytes(max(0, _MIN_FRAME - len(frame)))


def parse_answer(frame: bytes, command: int, index: int, ado: int) -> tuple[bytes, int] | None:
    """(data, working counter) when ``frame`` is the answer to our datagram, else None."""
    if len(frame) < _ETH.size + 2 + _DATAGRAM.size + 2:
        return None
    if _ETH.unpack_from(frame)[2] != ETHERTYPE_ECAT:
        return None
    ecat = _ECAT.unpack_from(frame, _ETH.size)[0]
    if ecat >> 12 != 1:
        return None
    at = _ETH.size + 2
    cmd, idx, _adp, got_ado, dlen, _irq = _DATAGRAM.unpack_from(frame, at)
    size = dlen & 0x07FF
    end = at + _DATAGRAM.size + size
    if (cmd, idx, got_ado) != (command, index, ado) or end + 2 > len(frame):
        return None
    return bytes(frame[at + _DATAGRAM.size : end]), _ECAT.unpack_from(frame, end)[0]


class RegisterPort:
    """Register reads and writes on ``interface`` (root or CAP_NET_RAW); see the module.

    ``timeout`` [s] per attempt, ``attempts`` in all. Use as a context manager.
    """

    def __init__(self, interface: str, timeout: float = 0.1, attempts: int = 4) -> None:
        self.interface = interface
        self.timeout = timeout
        self.attempts = max(1, attempts)
        self.sock: socket.socket | None = None

    def __enter__(self) -> RegisterPort:
        try:
            sock = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(ETHERTYPE_ECAT))
            sock.bind((self.interface, ETHERTYPE_ECAT))
        except OSError as exc:
            raise EtherCATError(
                f"cannot open a raw socket on {self.interface!r} for ESC register access: "
                f"{exc.strerror or exc}"
            ) from None
        sock.setblocking(False)
        self.sock = sock
        return self

    def __exit__(self, *exc: Any) -> None:
        if self.sock is not None:
            self.sock.close()
            self.sock = None

    def station_address(self, position: int, who: str) -> int:
        """The configured station address of the slave at 1-based line ``position`` (an
        auto-increment read of 0x0010: whatever address the master gave it)."""
        data = self._transact(APRD, 1 - position, STATION_ADDRESS, bytes(2), who, "0x0010")
        return int.from_bytes(data, "little")

    def write(self, station: int, ado: int, data: bytes, who: str) -> None:
        """FPWR ``data`` to register ``ado`` of the slave at configured address ``station``."""
        self._transact(FPWR, station, ado, bytes(data), who, f"0x{ado:04X}")

    def read(self, station: int, ado: int, length: int, who: str) -> bytes:
        """FPRD ``length`` bytes of register ``ado`` of the slave at ``station``."""
        return self._transact(FPRD, station, ado, bytes(length), who, f"0x{ado:04X}")

    def _transact(self, command: int, adp: int, ado: int, data: bytes, who: str, reg: str) -> bytes:
        assert self.sock is not None, "RegisterPort used outside its with block"
        name = {APRD: "APRD", FPRD: "FPRD", FPWR: "FPWR"}[command]
        for attempt in range(self.attempts):
            index = _FIRST_INDEX + attempt
            self.sock.send(build_frame(command, index, adp, ado, data))
            got = self._receive(command, index, ado)
            if got is None:
                continue  # lost or late: again, with another index
            payload, wkc = got
            if wkc != 1:
                raise EtherCATError(
                    f"{who}: {name} of ESC register {reg} was not performed (working counter "
                    f"{wkc}, expected 1)"
                )
            return payload
        raise EtherCATError(
            f"{who}: {name} of ESC register {reg}: no answer on {self.interface} after "
            f"{self.attempts} attempts"
        )

    def _receive(self, command: int, index: int, ado: int) -> tuple[bytes, int] | None:
        assert self.sock is not None
        deadline = time.monotonic() + self.timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            ready, _w, _x = select.select([self.sock], [], [], left)
            if not ready:
                return None
            try:
                frame, addr = self.sock.recvfrom(2048)
            except BlockingIOError:
                continue
            if addr[2] == _PACKET_OUTGOING:  # ours, or SOEM's, on the way out
                continue
            got = parse_answer(frame, command, index, ado)
            if got is not None:
                return got
