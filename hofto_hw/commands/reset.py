"""``hofto-hw reset``: reset the service's latched faults (refused while a cause persists)."""

from __future__ import annotations

import argparse

from hofto_hw.runtime.control_client import add_socket_argument, answer, request


def configure(parser: argparse.ArgumentParser) -> None:
    add_socket_argument(parser)


def run(args: argparse.Namespace) -> int:
    return answer(request(args.socket, "reset"))
