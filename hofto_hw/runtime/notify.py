"""sd_notify without libsystemd: one datagram to $NOTIFY_SOCKET (a path or an abstract '@'
name). Returns False when not under systemd (no NOTIFY_SOCKET); raises nothing."""

from __future__ import annotations

import os
import socket


def sd_notify(message: str) -> bool:
    """Send ``message`` (e.g. "READY=1", "WATCHDOG=1", "STATUS=...", "STOPPING=1")."""
    addr = os.environ.get("NOTIFY_SOCKET")
    if not addr:
        return False
    if addr.startswith("@"):
        addr = "\0" + addr[1:]  # abstract namespace
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC) as s:
            s.sendto(message.encode(), addr)
        return True
    except OSError:
        return False


def watchdog_interval(fraction: float = 0.5) -> float | None:
    """Seconds between WATCHDOG=1 pets (``fraction`` of $WATCHDOG_USEC), None if not set or
    meant for another process ($WATCHDOG_PID)."""
    usec = os.environ.get("WATCHDOG_USEC")
    pid = os.environ.get("WATCHDOG_PID")
    if not usec or (pid and pid.isdigit() and int(pid) != os.getpid()):
        return None
    try:
        return max(int(usec) * 1e-6 * fraction, 1e-3)
    except ValueError:
        return None
