"""A Unix-socket control channel for emulators: one JSON object per line, one JSON reply.

:func:`open_control_socket` never deletes anything but a stale socket: an existing path
that is not a socket is refused, a live socket (another emulator answering) too. The
socket is created with mode 0600 (umask set around bind), so only its owner can inject
faults.
"""

from __future__ import annotations

import json
import os
import socket
import stat
import threading
from collections.abc import Callable
from typing import Any

from hofto_hw.errors import UserError


def open_control_socket(path: str) -> socket.socket:
    """Listening Unix stream socket at ``path`` (mode 0600); raises UserError naming the path
    when it exists and is not a stale socket, or its folder is missing."""
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise UserError(f"--control {path}: folder {folder} does not exist")
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        st = None
    if st is not None:
        if not stat.S_ISSOCK(st.st_mode):
            raise UserError(f"--control {path}: exists and is not a socket; not replacing it")
        probe = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            probe.connect(path)
        except OSError:
            os.unlink(path)  # stale socket of a dead emulator
        else:
            raise UserError(f"--control {path}: another process is listening on it")
        finally:
            probe.close()
    srv = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    old = os.umask(0o177)
    try:
        srv.bind(path)
    finally:
        os.umask(old)
    os.chmod(path, 0o600)
    srv.listen(4)
    return srv


def serve_control(
    path: str, handler: Callable[[dict[str, Any]], dict[str, Any]], stop: threading.Event
) -> threading.Thread:
    """Serve ``handler`` on ``path`` in a daemon thread until ``stop`` is set; the socket
    file is removed on exit."""
    srv = open_control_socket(path)
    srv.settimeout(0.1)

    def loop() -> None:
        try:
            while not stop.is_set():
                try:
                    conn, _ = srv.accept()
                except TimeoutError:
                    continue
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
        finally:
            srv.close()
            try:
                if stat.S_ISSOCK(os.lstat(path).st_mode):
                    os.unlink(path)
            except FileNotFoundError:
                pass

    t = threading.Thread(target=loop, name="control-socket", daemon=True)
    t.start()
    return t
