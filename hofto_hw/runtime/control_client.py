"""Client side of the control socket for the CLI (``hofto-hw status|reset|stop|mode|enable``)
and tests: one request, one checked reply (hofto_hw/control_plane/protocol.py). Programs use
:class:`hofto_hw.client.Robot`."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from hofto_hw.errors import UserError

DEFAULT_SOCKET = Path("/run/hofto-hw/control.sock")


def add_socket_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--socket", type=Path, default=DEFAULT_SOCKET, help=f"control socket ({DEFAULT_SOCKET})"
    )


def add_service_socket_argument(parser: argparse.ArgumentParser) -> None:
    """``--socket`` of a command that goes through a running service when one answers and
    works offline otherwise (``home``, ``zero set``; :func:`running_service`)."""
    parser.add_argument(
        "--socket",
        type=Path,
        default=None,
        help="the running service's control socket (default: service.socket or "
        f"{DEFAULT_SOCKET} when a service answers there; none: offline)",
    )


def running_service(socket: Path | None, cfg: object = None) -> Path | None:
    """The control socket of a running service for a command that can go through it or
    work offline (``home``, ``zero set``): ``socket`` when given (UserError, one line, when
    nothing answers there), else the config's ``service.socket`` or the default socket when a
    service listens there, else None (no service: the command works offline)."""
    import socket as _socket

    def live(path: Path) -> bool:
        with _socket.socket(_socket.AF_UNIX, _socket.SOCK_STREAM) as probe:
            probe.settimeout(1.0)
            try:
                probe.connect(str(path))
            except OSError:
                return False
        return True

    if socket is not None:
        if not live(socket):
            raise UserError(f"--socket {socket}: no service answers there")
        return socket
    service = getattr(cfg, "service", None)
    for path in (getattr(service, "socket", None), DEFAULT_SOCKET):
        if path is not None and Path(path).exists() and live(Path(path)):
            return Path(path)
    return None


def request_of(line: str) -> dict[str, Any]:
    """A request in words (``status``, ``mode move``, ``enable on``, ``mode drag --record F``,
    ``mode replay F``, ``mode move-to q1,...,qn``; words split at blanks) -> its JSON form."""
    words = line.split()
    if not words:
        return {"cmd": ""}
    cmd, rest = words[0], words[1:]
    if cmd == "mode" and rest:
        what, more = rest[0], rest[1:]
        if what == "replay" and len(more) == 1:
            return {"cmd": "replay", "file": more[0]}
        if what == "move-to" and len(more) == 1:
            return {"cmd": "move_joints", "q": [float(v) for v in more[0].split(",")]}
        req: dict[str, Any] = {"cmd": "mode", "mode": what}
        if "--force" in more:
            req["force"] = True
            more = [w for w in more if w != "--force"]
        if len(more) == 2 and more[0] == "--record":
            req["record"] = more[1]
        return req
    if cmd == "enable" and len(rest) == 1 and rest[0] in ("on", "off"):
        return {"cmd": "enable", "on": rest[0] == "on"}
    return {"cmd": cmd}


def request(path: Path, req: str | dict[str, Any], timeout: float = 10.0) -> dict[str, Any]:
    """Send one request (a dict, or words for :func:`request_of`), return the checked reply;
    UserError (one line) when nobody answers or the reply is malformed."""
    from hofto_hw.client.connection import Connection

    if isinstance(req, str):
        req = request_of(req)
    with Connection(path, timeout=timeout) as conn:
        return conn.call(req)


def answer(reply: dict[str, Any]) -> int:
    """Print a reply's message; exit code 0 if ok, 1 if refused; UserError (the CLI prints
    it, exit 2) when the service refused bad input (``input_error``)."""
    if reply.get("input_error"):
        raise UserError(str(reply.get("message")))
    print(reply.get("message") or reply.get("error") or json.dumps(reply))
    return 0 if reply.get("ok") else 1
