"""A slave's CoE mailbox as SOEM's SDO transfers see it, for the master's and the scan's
unit tests (no bus): answers in order, late ones, SOEM's index-only matching."""

from __future__ import annotations

import pysoem

ABORT_NO_OBJECT = 0x06020000


class MailboxSlave:
    """A slave's mailbox as SOEM's ecx_SDOread sees it: answers come in order; before its
    request SOEM empties the read mailbox once without waiting; it takes the first SDO
    answer whose index matches (not the subindex), any other is an unexpected frame
    (PacketError), except an abort, taken whatever object it names (an object not in
    ``values`` is answered with one). ``late``: objects whose next answer is held until the
    master's next request (the master timed out on it: WkcError). A write is answered like a
    read. No SII (every category read is 0: none)."""

    name = "fake"
    man = 0x00000A5F
    id = 0x00402001
    rev = 1

    def __init__(self, values: dict[tuple[int, int], int], late: list[tuple[int, int]]) -> None:
        self.values = values
        self.late = list(late)
        self.pending: list[tuple[int, int]] = []  # answers in the read mailbox, in order
        self.held: list[tuple[int, int]] = []
        self.requests: list[tuple[int, int]] = []

    def eeprom_read(self, word: int) -> bytes:
        return bytes(4)

    def sdo_write(self, index: int, sub: int, data: bytes) -> None:
        self.sdo_read(index, sub)

    def sdo_read(self, index: int, sub: int) -> bytes:
        if self.pending:
            self.pending.pop(0)  # SOEM's drain: one frame, no wait
        self.requests.append((index, sub))
        self.pending.extend(self.held)  # the master asks again: the late ones come now
        self.held.clear()
        if (index, sub) in self.late:
            self.late.remove((index, sub))
            self.held.append((index, sub))
        else:
            self.pending.append((index, sub))
        if not self.pending:
            raise pysoem.WkcError(wkc=0)
        answer = self.pending.pop(0)
        if answer not in self.values:
            raise pysoem.SdoError(1, index, sub, ABORT_NO_OBJECT, "object does not exist")
        if answer[0] != index:
            raise pysoem.PacketError(1, 1)  # "unexpected frame returned"
        return self.values[answer].to_bytes(4, "little")
