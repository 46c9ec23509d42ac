"""The master's retry rules without a bus (no root): which pysoem failures are retried,
which are not, and what the user reads when retries run out."""

from __future__ import annotations

import pysoem
import pytest

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
    slave = FakeSlave([pysoem.WkcError(wkc=0), pysoem.PacketError(1, 1), b"\x10\x23"])
    transport.slaves = [slave]
    assert transport.read_value(0, 0x603F, 0, "u16") == 0x2310
    assert slave.calls == 3 and transport.mailbox_retried == 2


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
    slave = FakeSlave([pysoem.PacketError(1, 99)] * 3)  # a code pysoem cannot describe
    transport.slaves = [slave]
    with pytest.raises(EtherCATError) as err:
        transport.sdo_read(0, 0x1018, 1)
    assert isinstance(err.value, TransportError)
    msg = str(err.value)
    assert msg.startswith("slave 1 (joint_1) on ecm0: SDO read 0x1018:01 failed after 3 attempts")
    assert "\n" not in msg and slave.calls == 3


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
