"""A Unix-socket control channel for emulators: one JSON object per line, one JSON reply.

:func:`open_control_socket` never deletes anything but a stale socket: an existing path
that is not a socket is refused, a live socket (another emulator answering) too. The
socket is created with mode 0600 (umask set around bind), so only its owner can inject
faults; on exit an emulator removes the socket file only if it is still the one it made.
Both emulators (EtherCAT and CANopen) use these functions.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import stat
import threading
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


def answer(conn: socket.socket, handler: Callable[[dict[str, Any]], dict[str, Any]]) -> None:
    """One request on an accepted connection: read a JSON line, reply with ``handler``'s JSON
    line (a bad request gets ``{"ok": false, "error": ...}``); closes ``conn``."""
    with conn:
        conn.settimeout(2.0)
        data = b""
        try:
            while not data.endswith(b"\n"):
                chunk = conn.recv(4096)
                if not chunk:
                    break
                data += chunk
            try:
                request = json.loads(data.decode() or "{}")
                reply = handler(request if isinstance(request, dict) else {})
            except json.JSONDecodeError as exc:
                reply = {"ok": False, "error": f"bad JSON: {exc}"}
            conn.sendall(json.dumps(reply).encode() + b"\n")
        except OSError:
            pass


def serve_control(
    path: str, handler: Callable[[dict[str, Any]], dict[str, Any]], stop: threading.Event
) -> threading.Thread:
    """Serve ``handler`` on ``path`` in a daemon thread until ``stop`` is set; the socket
    file is removed on exit."""
    srv = open_control_socket(path)
    st = os.lstat(path)
    ident = (st.st_dev, st.st_ino)
    srv.settimeout(0.1)

    def loop() -> None:
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
