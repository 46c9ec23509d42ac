"""``hofto-hw stop``: stop the arm of the running service (category of stop_request),
through the stop socket beside ``--socket`` (``<socket>.stop``); without one (an older
service) through the control socket, saying so on stderr."""

from __future__ import annotations

import argparse
import sys

from hofto_hw.runtime.control_client import add_socket_argument, answer


def configure(parser: argparse.ArgumentParser) -> None:
    add_socket_argument(parser)


def run(args: argparse.Namespace) -> int:
    from hofto_hw.client.connection import send_stop

    reply, note = send_stop(args.socket)
    if note:
        print(f"hofto-hw stop: {note}", file=sys.stderr)
    return answer(reply)
