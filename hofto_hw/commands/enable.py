"""``hofto-hw enable on|off``: the enabling input of hand guiding over the control socket
(when ``drag.enable_input.source`` is ``socket``; tests, a GUI button)."""

from __future__ import annotations

import argparse

from hofto_hw.runtime.control_client import add_socket_argument, answer, request


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("state", choices=("on", "off"))
    add_socket_argument(parser)


def run(args: argparse.Namespace) -> int:
    return answer(request(args.socket, f"enable {args.state}"))
