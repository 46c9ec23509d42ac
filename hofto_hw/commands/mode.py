"""``hofto-hw mode hold|move``: change the running service's controller mode."""

from __future__ import annotations

import argparse

from hofto_hw.runtime.control_client import add_socket_argument, answer, request


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("mode", choices=("hold", "move"))
    add_socket_argument(parser)


def run(args: argparse.Namespace) -> int:
    return answer(request(args.socket, f"mode {args.mode}"))
