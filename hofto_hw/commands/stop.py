"""``hofto-hw stop``: stop the arm of the running service (category of stop_request)."""

from __future__ import annotations

import argparse

from hofto_hw.runtime.control_client import add_socket_argument, answer, request


def configure(parser: argparse.ArgumentParser) -> None:
    add_socket_argument(parser)


def run(args: argparse.Namespace) -> int:
    return answer(request(args.socket, "stop"))
