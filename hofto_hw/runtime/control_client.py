"""Client side of the control socket (``hofto-hw status|reset|stop|mode``)."""

from __future__ import annotations

import argparse
import json
import socket
from pathlib import Path
from typing import Any

from hofto_hw.errors import UserError

DEFAULT_SOCKET = Path("/run/hofto-hw/control.sock")


def add_socket_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--socket", type=Path, default=DEFAULT_SOCKET, help=f"control socket ({DEFAULT_SOCKET})"
    )


def request(path: Path, line: str, timeout: float = 10.0) -> dict[str, Any]:
    """Send one request line, return the JSON reply; UserError when nobody answers."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(timeout)
        try:
            s.connect(str(path))
        except FileNotFoundError:
            raise UserError(f"{path}: no control socket (is hofto-hw run serving it?)") from None
        except OSError as exc:
            raise UserError(f"{path}: cannot connect: {exc.strerror}") from None
        s.sendall((line + "\n").encode())
        data = s.makefile("r").readline()
    if not data:
        raise UserError(f"{path}: the service closed the connection without an answer")
    return json.loads(data)


def answer(reply: dict[str, Any]) -> int:
    """Print a reply's message; exit code 0 if ok, 1 if refused; UserError (the CLI prints
    it, exit 2) when the service refused bad input (``input_error``)."""
    if reply.get("input_error"):
        raise UserError(str(reply.get("message")))
    print(reply.get("message") or reply.get("error") or json.dumps(reply))
    return 0 if reply.get("ok") else 1
