"""A python-can bus on a UDP socket gets a deeper receive queue; others are left alone."""

from __future__ import annotations

import socket
from pathlib import Path

from drivers.canopen.socket_buffer import RECEIVE_BUFFER, widen_receive_buffer


class _OnSocket:
    """Stands for a python-can bus whose frames ride on a socket (udp_multicast)."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock

    def fileno(self) -> int:
        return self.sock.fileno()


def test_the_bus_socket_itself_is_widened() -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        before = s.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        got = widen_receive_buffer(_OnSocket(s))
        # the bus's own socket (still open after the duplicate closed), not only a copy
        assert got == s.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        rmem_max = int(Path("/proc/sys/net/core/rmem_max").read_text())
        if rmem_max > before // 2:  # the kernel lets it grow (always as root)
            assert got > before
        assert got <= 2 * RECEIVE_BUFFER


def test_a_bus_without_a_socket_is_left_alone() -> None:
    import can

    bus = can.Bus(interface="virtual", channel="hofto-socket-buffer")
    try:
        assert widen_receive_buffer(bus) == 0
    finally:
        bus.shutdown()
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        assert widen_receive_buffer(_OnSocket(s)) == 0
