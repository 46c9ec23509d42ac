"""A deeper receive queue for python-can buses that ride on a UDP socket (``udp_multicast``).

A CAN controller never drops a frame that was acknowledged; a UDP socket drops every datagram
that finds its receive buffer full. On ``udp_multicast`` every process on the channel gets
every frame (its own included), ~25 per 200 Hz cycle for six drives, so the kernel's default
buffer (208 KiB here, ~200 datagrams) overflows after a stall of ~40 ms, and a lost SYNC or
TPDO is a lost answer (:mod:`drivers.canopen.master` then counts the node one SYNC behind
until ``tpdo_resync``, longer than the bus-loss streak). Measured under load 13 on 2 cores:
9 of 3025 SYNCs never reached the emulated drives. :func:`widen_receive_buffer` asks for
4 MiB (the kernel caps it at ``net.core.rmem_max`` unless the process may force it).
"""

from __future__ import annotations

import contextlib
import socket
from typing import Any

#: receive buffer asked for [byte]: ~4000 datagrams, seconds of a stalled reader
RECEIVE_BUFFER = 4 * 1024 * 1024
_SO_RCVBUFFORCE = getattr(socket, "SO_RCVBUFFORCE", 33)  # Linux: beyond rmem_max (root)


def widen_receive_buffer(bus: Any, size: int = RECEIVE_BUFFER) -> int:
    """Enlarge the receive buffer of ``bus``'s socket when it has one (``bus.fileno()``, a
    datagram socket); returns the size the kernel reports [byte], 0 when there is no socket
    to widen (SocketCAN frames are not the concern, virtual buses have no socket)."""
    try:
        fd = bus.fileno()
    except (AttributeError, NotImplementedError, OSError):
        return 0
    if fd is None or fd < 0:
        return 0
    try:
        sock = socket.socket(fileno=socket.dup(fd))  # a duplicate: closing it keeps bus's
    except OSError:
        return 0
    with sock:
        if sock.type != socket.SOCK_DGRAM or sock.family not in (
            socket.AF_INET,
            socket.AF_INET6,
        ):
            return 0
        for option in (_SO_RCVBUFFORCE, socket.SO_RCVBUF):
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.SOL_SOCKET, option, size)
                break
        return int(sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF))
