"""The master's retry rules without a bus (no root): which pysoem failures are retried,
which are not, and what the user reads when retries run out."""

from __future__ import annotations

import pysoem
import pytest
from support.soem_mailbox import MailboxSlave

from drivers.errors import EtherCATError, SdoAbortError, TransportError
from drivers.ethercat.master import EtherCATTransport


class FakeSlave:
    """Stands in for a pysoem slave: answers from a script of results/exceptions."""

    def __init__(self, script: list[object], state: int = 0x08, al_status: int = 0) -> None:
        self.script = list(script)
        self.calls = 0
        self.state = state
        self.al_status = al_status
        self.written: list[int] = []

    def _next(self) -> object:
        self.calls += 1
        item = self.script.pop(0)
        if isinstance(item, BaseException):
            raise item
        return item

    def sdo_read(self, index: int, sub: int) -> bytes:
        return self._next()  # type: ignore[return-value]

    def sdo_write(self, index: int, sub: int, data: bytes) -> None:
        self._next()

    def write_state(self) -> int:
        self.written.append(self.state)
        return 1


@pytest.fixture
def transport(er3a_config) -> EtherCATTransport:
    t = EtherCATTransport("ecm0", er3a_config.bus.drives, 0.001, list(er3a_config.robot.joints))
    t.master = object()  # "open" for the SDO paths; nothing is sent
    return t


def test_a_lost_mailbox_answer_is_retried(transport: EtherCATTransport) -> None:
    fence = b"\x92\x01\x02\x00"  # 0x1000:00, read to bring the mailbox back in step
    slave = FakeSlave([pysoem.WkcError(wkc=0), fence, pysoem.PacketError(1, 1), fence, b"\x10\x23"])
    transport.slaves = [slave]
    assert transport.read_value(0, 0x603F, 0, "u16") == 0x2310
    assert slave.calls == 5 and transport.mailbox_retried == 2
    assert transport.mailbox_resynced == 2


def test_an_sdo_abort_is_the_drives_answer_and_not_retried(transport: EtherCATTransport) -> None:
    abort = pysoem.SdoError(1, 0x6072, 0, 0x06010002, "read only")
    slave = FakeSlave([abort, b"never"])
    transport.slaves = [slave]
    with pytest.raises(SdoAbortError) as err:
        transport.sdo_write(0, 0x6072, 0, b"\x00\x00")
    assert slave.calls == 1 and err.value.code == 0x06010002


def test_retries_run_out_with_one_line_naming_slave_and_access(
    transport: EtherCATTransport,
) -> None:
    transport.mailbox_retries = 2
    late = pysoem.PacketError(1, 99)  # a code pysoem cannot describe
    fence = b"\x92\x01\x02\x00"
    slave = FakeSlave([late, fence, late, fence, late])
    transport.slaves = [slave]
    with pytest.raises(EtherCATError) as err:
        transport.sdo_read(0, 0x1018, 1)
    assert isinstance(err.value, TransportError)
    msg = str(err.value)
    assert msg.startswith("slave 1 (joint_1) on ecm0: SDO read 0x1018:01 failed after 3 attempts")
    assert "\n" not in msg and slave.calls == 5


def test_only_an_expired_sm_watchdog_is_acknowledged(transport: EtherCATTransport) -> None:
    late = FakeSlave([], state=0x14, al_status=0x001B)  # the master was late
    refused = FakeSlave([], state=0x14, al_status=0x001A)  # a real refusal
    fine = FakeSlave([], state=0x08)
    transport.slaves = [late, refused, fine]
    assert transport._ack_watchdog_errors(0x08)
    assert late.written == [0x14, 0x08]  # acknowledge SAFE-OP + ERROR, then ask for OP
    assert refused.written == [] and fine.written == []
    late.state, late.al_status = 0x14, 0x001A
    assert not transport._ack_watchdog_errors(0x08)


IDENTITY = {(0x1018, 1): 0x00000A5F, (0x1018, 2): 0x00000DEC, (0x1000, 0): 0x00020192}
IDENTITY |= {(0x1C00, 0): 4, (0x1018, 0): 4, (0x6041, 0): 0x0237}


def test_a_late_answer_is_not_taken_for_the_next_read_of_another_subindex(
    transport: EtherCATTransport,
) -> None:
    """0x1018:01 times out; its answer comes with the next request. Without resync the read
    of 0x1018:02 takes it (SOEM compares the index only) and returns the vendor id."""
    transport.mailbox_retries = 0
    slave = MailboxSlave(IDENTITY, late=[(0x1018, 1)])
    transport.slaves = [slave]
    with pytest.raises(EtherCATError, match=r"SDO read 0x1018:01 failed after 1 attempts"):
        transport.sdo_read(0, 0x1018, 1)
    assert transport.read_value(0, 0x1018, 2, "u32") == 0x00000DEC
    assert transport.mailbox_resynced == 1 and slave.pending == []
    # the fence never used the failed object's index (a late answer would pass for it)
    fences = slave.requests[1:-1]
    assert fences and all(i != 0x1018 for i, _s in fences)


def test_a_retry_that_took_the_late_answer_leaves_its_own_behind_no_more(
    transport: EtherCATTransport,
) -> None:
    """Two late answers in a row: the retry of 0x1018:01 would take the first late answer
    (the right value) and leave its own for the read of 0x1018:02."""
    slave = MailboxSlave(IDENTITY, late=[(0x1018, 1), (0x1018, 1)])
    transport.slaves = [slave]
    assert transport.read_value(0, 0x1018, 1, "u32") == 0x00000A5F
    assert transport.read_value(0, 0x1018, 2, "u32") == 0x00000DEC
    assert transport.mailbox_resynced == 2


def test_a_mailbox_that_stays_out_of_step_is_refused_in_one_line(
    transport: EtherCATTransport,
) -> None:
    transport.mailbox_retries = 0
    slave = MailboxSlave(IDENTITY, late=[(0x1018, 1), (0x1000, 0), (0x1C00, 0), (0x6041, 0)])
    transport.slaves = [slave]
    with pytest.raises(EtherCATError):
        transport.sdo_read(0, 0x1018, 1)
    with pytest.raises(EtherCATError) as err:
        transport.sdo_read(0, 0x1018, 2)
    assert str(err.value) == (
        "slave 1 (joint_1) on ecm0: SDO read 0x1018:02 not sent: mailbox out of step since an "
        "SDO transfer of 0x1018 got no valid answer, and none of 0x1000:00, 0x1C00:00, "
        "0x6041:00 answered cleanly either"
    )
    assert (0x1018, 2) not in slave.requests
