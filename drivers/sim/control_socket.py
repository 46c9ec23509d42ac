"""A Unix-socket control channel for emulators: one JSON object per line, one JSON reply.

:func:`open_control_socket` never deletes anything but a stale socket: an existing path
that is not a socket is refused, a live socket (another emulator answering) too. The
socket is created with mode 0600 (umask set around bind), so only its owner can inject
faults; on exit an emulator removes the socket file only if it is still the one it made.
Both emulators (EtherCAT and CANopen) use these functions.

An emulator's frame path never waits for a control client: the EtherCAT emulator serves its
control socket from its frame loop through :class:`ControlConnections` (non-blocking: a
request is taken once its whole line has arrived, a reply is sent as the client reads it),
the CANopen emulator from a thread of its own (:func:`serve_control`). Before, the EtherCAT
emulator read each request and wrote each reply blocking, in the thread that answers frames:
a client preempted between its connect and its line (a test process on a loaded 2-core
machine) or slow to read a long reply (``trace_read``) held every frame until it ran again.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import stat
import threading
import time
from collections.abc import Callable
from typing import Any

from hofto_hw.errors import UserError


def check_control_path(path: str | os.PathLike[str], option: str = "--control") -> None:
    """Refuse a control-socket path that is not free or a stale socket (UserError, one line
    naming ``option``, the command-line option that gave the path).

    Only a socket nobody listens on may be replaced; a regular file, a folder, a link, a
    live socket or a path in a missing folder is refused and left alone.
    """
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise UserError(f"{option}: folder {folder!r} for the socket {path!r} does not exist")
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return
    if not stat.S_ISSOCK(st.st_mode):
        kind = "a folder" if stat.S_ISDIR(st.st_mode) else "not a socket"
        raise UserError(f"{option}: {path!r} exists and is {kind}; refusing to replace it")
    if _socket_is_live(path):
        raise UserError(f"{option}: {path!r} is in use by another process; refusing to replace it")


def claim_control_path(path: str | os.PathLike[str], option: str = "--control") -> None:
    """:func:`check_control_path`, then remove the stale socket there (the caller binds
    next). The emulators' and ``hofto-hw run``'s control sockets both come through here."""
    check_control_path(path, option)
    with contextlib.suppress(FileNotFoundError):
        if stat.S_ISSOCK(os.lstat(path).st_mode):
            os.unlink(path)


def _socket_is_live(path: str) -> bool:
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as probe:
        probe.settimeout(0.5)
        try:
            probe.connect(path)
        except (ConnectionRefusedError, FileNotFoundError):
            return False
        except OSError:
            return True  # busy or not ours to judge: leave it
    return True


def open_control_socket(path: str) -> socket.socket:
    """Listening Unix stream socket at ``path``, mode 0600 (owner only: it can stop the
    emulator and inject faults). A stale socket there is replaced; anything else is
    refused (:func:`claim_control_path`)."""
    claim_control_path(path)
    srv = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    old_mask = os.umask(0o177)  # the socket file is created with mode 0600
    try:
        srv.bind(path)
    except OSError as exc:
        srv.close()
        raise UserError(f"--control: cannot create the socket {path!r}: {exc.strerror}") from None
    finally:
        os.umask(old_mask)
    os.chmod(path, 0o600)
    srv.listen(4)
    srv.setblocking(False)
    return srv


def remove_own_socket(path: str, ident: tuple[int, int]) -> None:
    """Unlink ``path`` only if it is still the socket file this process created."""
    with contextlib.suppress(OSError):
        st = os.lstat(path)
        if stat.S_ISSOCK(st.st_mode) and (st.st_dev, st.st_ino) == ident:
            os.unlink(path)


Handler = Callable[[dict[str, Any]], dict[str, Any]]

#: [s] a control client has this long to send its line and read the reply
CLIENT_TIMEOUT = 2.0


def _reply(data: bytes, handler: Handler) -> bytes:
    """``handler``'s JSON line for the request line ``data`` (a bad request gets
    ``{"ok": false, "error": ...}``)."""
    try:
        request = json.loads(data.decode() or "{}")
        reply = handler(request if isinstance(request, dict) else {})
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        reply = {"ok": False, "error": f"bad JSON: {exc}"}
    return json.dumps(reply).encode() + b"\n"


def answer(conn: socket.socket, handler: Handler) -> None:
    """One request on an accepted connection: read a JSON line, reply with ``handler``'s JSON
    line; closes ``conn``. Blocks up to :data:`CLIENT_TIMEOUT` on the client: for a thread
    that does nothing else (:func:`serve_control`)."""
    with conn:
        conn.settimeout(CLIENT_TIMEOUT)
        data = b""
        try:
            while not data.endswith(b"\n"):
                chunk = conn.recv(4096)
                if not chunk:
                    break
                data += chunk
            conn.sendall(_reply(data, handler))
        except OSError:
            pass


class _Client:
    __slots__ = ("conn", "data", "deadline", "out")

    def __init__(self, conn: socket.socket, deadline: float) -> None:
        self.conn = conn
        self.data = b""
        self.out: memoryview | None = None  # the reply not yet sent
        self.deadline = deadline


class ControlConnections:
    """The control socket ``srv`` (non-blocking, :func:`open_control_socket`) served from a
    ``select`` loop that has other work: nothing here blocks. Select on :meth:`readers`
    and :meth:`writers` beside your own descriptors, then call :meth:`ready` with what
    ``select`` returned; it accepts, reads, calls ``handler`` once a whole line is in and
    sends the reply as far as the client takes it. A client that has not sent its line or
    read its reply within :data:`CLIENT_TIMEOUT` is dropped."""

    def __init__(self, srv: socket.socket, handler: Handler) -> None:
        self.srv = srv
        self.handler = handler
        self._clients: dict[socket.socket, _Client] = {}

    def readers(self) -> list[socket.socket]:
        return [self.srv, *(c.conn for c in self._clients.values() if c.out is None)]

    def writers(self) -> list[socket.socket]:
        return [c.conn for c in self._clients.values() if c.out is not None]

    def ready(self, readable: list[Any], writable: list[Any]) -> int:
        """Serve what ``select`` found ready; returns the number of requests handled."""
        handled = 0
        now = time.monotonic()
        if self.srv in readable:
            self._accept(now)
        for conn in list(self._clients):
            c = self._clients[conn]
            if conn in readable and c.out is None:
                handled += self._read(c)
            if conn in writable and c.out is not None:
                self._write(c)
            if conn in self._clients and now > c.deadline:
                self._drop(c)
        return handled

    def close(self) -> None:
        for c in list(self._clients.values()):
            self._drop(c)

    def _accept(self, now: float) -> None:
        while True:
            try:
                conn, _ = self.srv.accept()
            except OSError:  # none waiting (EAGAIN), or EMFILE and the like: the next select
                return
            conn.setblocking(False)
            self._clients[conn] = _Client(conn, now + CLIENT_TIMEOUT)

    def _read(self, c: _Client) -> int:
        try:
            chunk = c.conn.recv(65536)
        except (BlockingIOError, InterruptedError):
            return 0
        except OSError:
            self._drop(c)
            return 0
        c.data += chunk
        if chunk and not c.data.endswith(b"\n"):
            return 0
        c.out = memoryview(_reply(c.data, self.handler))
        self._write(c)
        return 1

    def _write(self, c: _Client) -> None:
        assert c.out is not None
        try:
            sent = c.conn.send(c.out)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            self._drop(c)
            return
        c.out = c.out[sent:]
        if not len(c.out):
            self._drop(c)

    def _drop(self, c: _Client) -> None:
        self._clients.pop(c.conn, None)
        with contextlib.suppress(OSError):
            c.conn.close()


def serve_control(
    path: str,
    handler: Handler,
    stop: threading.Event,
    setup: Callable[[], None] | None = None,
) -> threading.Thread:
    """Serve ``handler`` on ``path`` in a daemon thread until ``stop`` is set; the socket
    file is removed on exit. ``setup`` runs first in that thread (e.g. its priority:
    drivers.sim.pacing.control_beside_frames)."""
    srv = open_control_socket(path)
    st = os.lstat(path)
    ident = (st.st_dev, st.st_ino)
    srv.settimeout(0.1)

    def loop() -> None:
        if setup is not None:
            setup()
        try:
            while not stop.is_set():
                try:
                    conn, _ = srv.accept()
                except TimeoutError:
                    continue
                answer(conn, handler)
        finally:
            srv.close()
            remove_own_socket(path, ident)

    t = threading.Thread(target=loop, name="control-socket", daemon=True)
    t.start()
    return t
