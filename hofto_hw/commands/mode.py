"""``hofto-hw mode hold|move|drag``: change the running service's controller mode (drag:
hand guiding, entered only from standstill with no latched fault)."""

from __future__ import annotations

import argparse

from hofto_hw.runtime.control_client import add_socket_argument, answer, request


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("mode", choices=("hold", "move", "drag"))
    add_socket_argument(parser)


def run(args: argparse.Namespace) -> int:
    return answer(request(args.socket, f"mode {args.mode}"))
