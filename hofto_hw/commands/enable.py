"""``hofto-hw enable on|off``: the enabling input of hand guiding over the control socket
(when ``drag.enable_input.source`` is ``socket``; tests, a GUI button).

The remote enabling input is a lease (``drag.enable_input.lease``): ``enable on`` holds it,
renewing it, until Ctrl-C / SIGTERM or ``--seconds`` have passed, then lets go (a release:
category 2 stop while dragging). If this command dies, the lease lapses by itself.
"""

from __future__ import annotations

import argparse
import math
import signal
import time

from hofto_hw.errors import UserError
from hofto_hw.runtime.control_client import add_socket_argument, answer


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("state", choices=("on", "off"))
    parser.add_argument(
        "--seconds", type=float, default=None, help="on: hold it this long (default: until Ctrl-C)"
    )
    add_socket_argument(parser)


def run(args: argparse.Namespace) -> int:
    from hofto_hw.client.connection import Connection

    secs = args.seconds
    if secs is not None and (not math.isfinite(secs) or secs <= 0.0):
        raise UserError(f"--seconds: must be a finite number of seconds > 0, got {secs}")
    if secs is not None and args.state == "off":
        raise UserError("--seconds: only with enable on")
    with Connection(args.socket) as conn:
        if args.state == "off":
            return answer(conn.call({"cmd": "enable", "on": False}))
        r = conn.call({"cmd": "enable", "on": True})
        if not r["ok"]:
            return answer(r)
        lease = float(r.get("lease_s", 0.25))
        print(f"enabling input held (lease {lease:g} s, renewed); Ctrl-C lets go", flush=True)
        done = [False]
        old = signal.signal(signal.SIGTERM, lambda *_: done.__setitem__(0, True))
        end = math.inf if secs is None else time.monotonic() + secs
        try:
            while not done[0] and time.monotonic() < end:
                time.sleep(lease / 3.0)
                r = conn.call({"cmd": "enable", "on": True})
                if not r["ok"]:
                    return answer(r)
        except KeyboardInterrupt:
            pass
        finally:
            signal.signal(signal.SIGTERM, old)
        return answer(conn.call({"cmd": "enable", "on": False}))
