"""One connection to the control socket: a request line out, a checked reply line in.

Every way a reply can be wrong — nobody listening, no answer in time, the connection closed
early, a line too long, not UTF-8, not JSON, nested too deep, ``ok`` not a bool, a NaN or
infinite number — is a :class:`ServiceError` (a one-line ``UserError``) naming the socket,
never a traceback.
"""

from __future__ import annotations

import os
import socket
import time
from pathlib import Path
from typing import Any

from hofto_hw.control_plane import protocol as pr
from hofto_hw.errors import UserError


class ServiceError(UserError):
    """The service could not be asked, or its answer is malformed (one line)."""


class Refused(UserError):
    """The service answered ``ok: false``; the message is its one-line reason."""

    def __init__(self, message: str, reply: dict[str, Any] | None = None) -> None:
        super().__init__(message)
        self.reply = reply or {}
        self.input_error = bool(self.reply.get("input_error"))


class Connection:
    """A connection to the socket at ``path``; :meth:`call` sends one request and returns
    its reply (a dict with ``ok``). Not shared between threads without a lock."""

    def __init__(self, path: Path | str, timeout: float = 10.0) -> None:
        self.path = Path(path)
        self.timeout = float(timeout)
        self._buf = bytearray()
        self._next_id = 1
        s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM | socket.SOCK_CLOEXEC)
        s.settimeout(self.timeout)
        try:
            s.connect(os.fspath(self.path))
        except FileNotFoundError:
            s.close()
            raise ServiceError(
                f"{self.path}: no control socket (is hofto-hw run serving it?)"
            ) from None
        except TimeoutError:
            s.close()
            raise ServiceError(f"{self.path}: no answer within {self.timeout:g} s") from None
        except OSError as exc:
            s.close()
            raise ServiceError(f"{self.path}: cannot connect: {exc.strerror or exc}") from None
        self.sock = s

    def __enter__(self) -> Connection:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        try:
            self.sock.close()
        except OSError:
            pass

    def call(self, req: dict[str, Any], timeout: float | None = None) -> dict[str, Any]:
        """Send ``req``; return the reply with the same id (replies of other ids are
        skipped: a stop answered ahead of an earlier request)."""
        rid = self._next_id
        self._next_id += 1
        req = {**req, "id": rid}
        try:
            line = pr.dumps(req)
        except ValueError:
            raise ServiceError(f"{req.get('cmd')}: a number in the request is not finite") from None
        try:
            self.sock.sendall(line)
        except OSError as exc:
            raise ServiceError(f"{self.path}: cannot send: {exc.strerror or exc}") from None
        end = time.monotonic() + (self.timeout if timeout is None else timeout)
        while True:
            rep = self._read_reply(end)
            if rep.get("id", rid) == rid:
                rep.pop("id", None)
                return rep

    def _read_reply(self, end: float) -> dict[str, Any]:
        buf = self._buf
        while True:
            i = buf.find(b"\n")
            if i >= 0:
                raw = bytes(buf[:i])
                del buf[: i + 1]
                try:
                    return pr.parse_reply(raw)
                except pr.ProtocolError as exc:
                    raise ServiceError(f"{self.path}: malformed answer: {exc}") from None
            if len(buf) > pr.MAX_REPLY:
                raise ServiceError(
                    f"{self.path}: malformed answer: longer than {pr.MAX_REPLY} bytes"
                )
            left = end - time.monotonic()
            if left <= 0:
                raise ServiceError(f"{self.path}: no answer within {self.timeout:g} s")
            self.sock.settimeout(left)
            try:
                data = self.sock.recv(65536)
            except TimeoutError:
                raise ServiceError(f"{self.path}: no answer within {self.timeout:g} s") from None
            except OSError as exc:
                raise ServiceError(f"{self.path}: connection lost: {exc.strerror or exc}") from None
            if not data:
                raise ServiceError(
                    f"{self.path}: the service closed the connection without an answer"
                )
            buf += data


def send_stop(control: Path | str, timeout: float = 10.0) -> tuple[dict[str, Any], str]:
    """Stop the arm of the service whose control socket is ``control``: through the stop
    socket beside it (``<control>.stop``, served by a process that does nothing else, so no
    request of any client queues ahead of it). Returns (the checked reply, a note): the note
    is "" when the stop socket answered, else one line saying that the stop went through the
    control socket's ``stop`` (no stop socket there, e.g. an older service, or it did not
    answer: an operator's stop errs on the side of being sent twice)."""
    sp = pr.stop_path(control)
    try:
        with Connection(sp, timeout) as c:
            return c.call({"cmd": "stop"}), ""
    except ServiceError as exc:
        why = "no stop socket" if not os.path.lexists(sp) else f"the stop socket failed ({exc})"
    with Connection(control, timeout) as c:
        rep = c.call({"cmd": "stop"})
    return rep, f"{sp}: {why}: the stop went through the control socket (an older service?)"
