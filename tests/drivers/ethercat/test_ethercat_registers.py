"""ESC register access beside SOEM (drivers/ethercat/registers.py): the frames it builds and
the answers it takes, through the emulator's frame processor; on a veth pair (root), a line
of emulated slaves answering it, and frames going out on the interface (SOEM's, or a copy
of ours) never taken for an answer."""

from __future__ import annotations

import contextlib
import socket
import struct
import threading
from collections.abc import Iterator

import pytest

from drivers.ethercat import registers as reg
from drivers.ethercat.errors import EtherCATError
from drivers.sim.esc import datagram
from drivers.sim.esc import registers as r
from drivers.sim.esc.description import SlaveDescription
from drivers.sim.esc.esc import Esc


def _line(n: int) -> list[Esc]:
    desc = SlaveDescription(vendor_id=0x2BF, product_code=0x1, revision=0x1)
    slaves = [Esc(desc, None, i, n) for i in range(n)]
    for i, s in enumerate(slaves):  # station addresses as SOEM gives them
        s.write(r.STATION_ADDRESS, struct.pack("<H", 0x1001 + i))
    return slaves


def _through(frame: bytes, slaves: list[Esc]) -> bytes:
    buf = bytearray(frame)
    datagram.process_frame(buf, len(buf), slaves)
    return bytes(buf)


def test_our_datagram_indices_are_ones_soem_never_uses() -> None:
    """SOEM's frame buffers are indices 0..15 (EC_MAXBUF); ecx_inframe drops any other."""
    frame = reg.build_frame(reg.FPWR, 0xA0, 0x1001, reg.CYCLIC_UNIT_CONTROL, b"\x30")
    assert frame[reg._ETH.size + 3] >= reg.SOEM_MAX_INDEX
    assert len(frame) == 60 and frame[12:14] == b"\x88\xa4"


def test_a_write_and_its_read_back_through_a_line_of_slaves() -> None:
    slaves = _line(3)
    ado = reg.CYCLIC_UNIT_CONTROL
    out = reg.build_frame(reg.FPWR, 0xA0, 0x1003, ado, b"\x30")
    assert reg.parse_answer(out, reg.FPWR, 0xA0, ado) == (b"\x30", 0)  # not performed yet
    back = _through(out, slaves)
    assert reg.parse_answer(back, reg.FPWR, 0xA0, ado) == (b"\x30", 1)
    assert [s.mem[ado] for s in slaves] == [0, 0, 0x30]
    read = _through(reg.build_frame(reg.FPRD, 0xA1, 0x1003, ado, b"\0"), slaves)
    assert reg.parse_answer(read, reg.FPRD, 0xA1, ado) == (b"\x30", 1)
    # another index, command or register is not the answer to ours
    assert reg.parse_answer(read, reg.FPRD, 0xA0, ado) is None
    assert reg.parse_answer(read, reg.FPWR, 0xA1, ado) is None
    assert reg.parse_answer(read, reg.FPRD, 0xA1, ado + 1) is None


def test_the_station_address_is_read_by_line_position() -> None:
    slaves = _line(3)
    frame = _through(reg.build_frame(reg.APRD, 0xA0, 1 - 2, reg.STATION_ADDRESS, bytes(2)), slaves)
    assert reg.parse_answer(frame, reg.APRD, 0xA0, reg.STATION_ADDRESS) == (b"\x02\x10", 1)


def test_reserved_bits_of_the_cyclic_unit_control_read_zero() -> None:
    """What an ESC does, and what makes a read-back differ from the write."""
    slaves = _line(1)
    _through(reg.build_frame(reg.FPWR, 0xA0, 0x1001, reg.CYCLIC_UNIT_CONTROL, b"\xff"), slaves)
    assert slaves[0].mem[reg.CYCLIC_UNIT_CONTROL] == 0x31


# ----------------------------------------------------------------------- on a veth


@contextlib.contextmanager
def _answering(iface: str, slaves: list[Esc]) -> Iterator[None]:
    """A thread answering every EtherCAT frame arriving on ``iface`` through ``slaves``."""
    sock = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(reg.ETHERTYPE_ECAT))
    sock.bind((iface, reg.ETHERTYPE_ECAT))
    sock.settimeout(0.05)
    stop = threading.Event()

    def serve() -> None:
        while not stop.is_set():
            try:
                frame, addr = sock.recvfrom(2048)
            except TimeoutError:
                continue
            if addr[2] == 4:  # our own answer going out
                continue
            back = bytearray(_through(frame, slaves))
            back[6] |= 0x02
            sock.send(bytes(back))

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join()
        sock.close()


@pytest.mark.root
def test_a_line_answers_the_port_on_a_veth_pair() -> None:
    from support.rootnet import veth_pair

    slaves = _line(3)
    with veth_pair("rgm", "rgs") as (master, slave), _answering(slave, slaves):
        with reg.RegisterPort(master, timeout=1.0) as port:
            station = port.station_address(2, "slave 2")
            assert station == 0x1002
            port.write(station, reg.CYCLIC_UNIT_CONTROL, b"\x30", "slave 2")
            assert port.read(station, reg.CYCLIC_UNIT_CONTROL, 1, "slave 2") == b"\x30"
            with pytest.raises(EtherCATError) as err:  # no slave at that address: wkc 0
                port.read(0x1009, reg.CYCLIC_UNIT_CONTROL, 1, "slave 9")
    assert [s.mem[reg.CYCLIC_UNIT_CONTROL] for s in slaves] == [0, 0x30, 0]
    assert str(err.value) == (
        "slave 9: FPRD of ESC register 0x0980 was not performed (working counter 0, expected 1)"
    )


@pytest.mark.root
def test_frames_that_answer_another_datagram_are_not_taken_for_answers() -> None:
    """Frames arriving on the master's interface that answer something else (SOEM's own
    frames come back with indices below 16; another register; another command) are not the
    answer the port waits for, however their working counter reads; with no real answer
    the port says so in one line after its attempts."""
    from support.rootnet import veth_pair

    ado = reg.CYCLIC_UNIT_CONTROL
    others = [(reg.FPRD, 5, ado), (reg.FPRD, 0xA0, ado + 1), (reg.FPWR, 0xA0, ado),
              (reg.FPWR, 0xA1, ado)]  # fmt: skip
    with veth_pair("rom", "ros") as (master, slave):
        far = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(reg.ETHERTYPE_ECAT))
        far.bind((slave, reg.ETHERTYPE_ECAT))
        stop = threading.Event()
        sent = [0]

        def answer_something_else() -> None:
            while not stop.wait(0.005):
                for command, index, where in others:
                    fake = bytearray(reg.build_frame(command, index, 0x1001, where, b"\x30"))
                    fake[reg._ETH.size + 2 + reg._DATAGRAM.size + 1] = 1  # wkc 1
                    fake[6] |= 0x02  # the source MAC an ESC returns
                    far.send(bytes(fake))
                    sent[0] += 1

        thread = threading.Thread(target=answer_something_else, daemon=True)
        thread.start()
        try:
            with reg.RegisterPort(master, timeout=0.2, attempts=2) as port:
                with pytest.raises(EtherCATError) as err:
                    port.read(0x1001, ado, 1, "slave 1")
        finally:
            stop.set()
            thread.join()
            far.close()
    assert sent[0] > 0
    assert str(err.value) == (
        f"slave 1: FPRD of ESC register 0x0980: no answer on {master} after 2 attempts"
    )
