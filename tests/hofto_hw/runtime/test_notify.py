"""sd_notify against a test NOTIFY_SOCKET: READY/STATUS/STOPPING, the watchdog is petted at
its interval while the heartbeat advances and not when it stands still."""

from __future__ import annotations

import os
import socket

import pytest

from hofto_hw.runtime.notify import Notifier, NotifyError, Watchdog

STATE_TIMEOUT = 60.0


@pytest.fixture(params=["path", "abstract"])
def notify_socket(request, tmp_path):
    """(env value of NOTIFY_SOCKET, bound datagram socket to read from)."""
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    if request.param == "path":
        address = str(tmp_path / "notify.sock")
        sock.bind(address)
    else:
        name = f"hofto-hw-test-{os.getpid()}-{id(sock)}"
        sock.bind("\0" + name)
        address = "@" + name
    sock.settimeout(STATE_TIMEOUT)
    yield address, sock
    sock.close()


def test_ready_status_stopping_reach_the_socket(notify_socket):
    address, sock = notify_socket
    n = Notifier({"NOTIFY_SOCKET": address})
    assert n.enabled and n.watchdog_interval is None
    n.ready("running at 1000 Hz")
    assert sock.recv(4096) == b"READY=1\nSTATUS=running at 1000 Hz"
    n.status("fault: collision")
    assert sock.recv(4096) == b"STATUS=fault: collision"
    n.stopping()
    assert sock.recv(4096) == b"STOPPING=1"
    n.close()


def test_without_systemd_nothing_is_sent_and_nothing_fails():
    n = Notifier({})
    assert not n.enabled and n.watchdog_interval is None
    n.ready()
    n.stopping()
    assert Watchdog(n, lambda: 0).start()._thread is None


def test_a_missing_socket_is_an_error_naming_it(tmp_path):
    n = Notifier({"NOTIFY_SOCKET": str(tmp_path / "gone.sock")})
    with pytest.raises(NotifyError, match=r"gone\.sock"):
        n.ready()


def test_watchdog_interval_is_half_of_watchdog_usec_and_respects_watchdog_pid(notify_socket):
    address, _ = notify_socket
    env = {"NOTIFY_SOCKET": address, "WATCHDOG_USEC": "2000000"}
    assert Notifier(env).watchdog_interval == pytest.approx(1.0)
    assert Notifier({**env, "WATCHDOG_PID": str(os.getpid())}).watchdog_interval == 1.0
    assert Notifier({**env, "WATCHDOG_PID": "1"}).watchdog_interval is None


def test_watchdog_pets_only_while_the_heartbeat_advances(notify_socket):
    address, sock = notify_socket
    beat = [0]
    dog = Watchdog(Notifier({"NOTIFY_SOCKET": address}), lambda: beat[0])
    assert dog.check()  # first check: alive
    assert sock.recv(64) == b"WATCHDOG=1"
    assert not dog.check()  # loop hung: no pet
    beat[0] += 1
    assert dog.check()
    assert sock.recv(64) == b"WATCHDOG=1"
    assert (dog.pets, dog.missed) == (2, 1)
    sock.setblocking(False)
    with pytest.raises(BlockingIOError):  # the hung check sent nothing
        sock.recv(64)


def test_watchdog_thread_pets_repeatedly_while_alive(notify_socket):
    address, sock = notify_socket
    beat = [0]

    def heartbeat() -> int:
        beat[0] += 1
        return beat[0]

    env = {"NOTIFY_SOCKET": address, "WATCHDOG_USEC": "40000"}  # pet every 20 ms
    dog = Watchdog(Notifier(env), heartbeat).start()
    try:
        for _ in range(3):
            assert sock.recv(64) == b"WATCHDOG=1"
    finally:
        dog.stop()
    assert dog.pets >= 3 and dog.errors == 0
