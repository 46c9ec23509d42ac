"""``hofto-hw mode hold|move|drag|replay``: change the running service's controller mode.

- ``drag``: hand guiding, entered only from standstill with no latched fault;
  ``--record FILE`` records the taught path (joint positions with time stamps) while the
  enabling input is held and writes FILE when the drag ends (a new file; ``--force`` replaces
  an existing one).
- ``replay FILE``: a jerk-limited move to the taught path's start, then the path time-scaled
  into the ``motion:`` limits.
- ``move``: the demo path; ``move --joints q1,...,qn`` [rad, or ``--degrees``]: a jerk-limited
  move to that joint target.

Bad input (a missing or bad file, a target out of limits, ...) is one line and exit 2; a
refusal of the running service (a latched stop, not at standstill) exit 1.
"""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path

from hofto_hw.errors import UserError
from hofto_hw.runtime.control_client import add_socket_argument, answer, request


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("mode", choices=("hold", "move", "drag", "replay"))
    parser.add_argument("file", nargs="?", type=Path, help="replay: the taught-path file")
    parser.add_argument(
        "--record", type=Path, default=None, help="drag: write the taught path to this new file"
    )
    parser.add_argument("--force", action="store_true", help="--record: replace an existing file")
    parser.add_argument("--joints", default=None, help="move: jerk-limited move to q1,...,qn [rad]")
    parser.add_argument("--degrees", action="store_true", help="--joints are in degrees")
    add_socket_argument(parser)


def request_of(args: argparse.Namespace) -> dict:
    """The control-socket request for ``args``; UserError (one line) for a bad combination."""
    from hofto_hw.runtime.teach import parse_joints

    mode = args.mode
    if args.file is not None and mode != "replay":
        raise UserError(f"mode {mode}: takes no FILE ({args.file}); only mode replay does")
    if args.record is not None and mode != "drag":
        raise UserError(f"--record: only with mode drag, not mode {mode}")
    if args.force and args.record is None:
        raise UserError("--force: only with --record FILE")
    if args.joints is not None and mode != "move":
        raise UserError(f"--joints: only with mode move, not mode {mode}")
    if args.degrees and args.joints is None:
        raise UserError("--degrees: only with --joints")
    if mode == "replay":
        if args.file is None:
            raise UserError("mode replay: needs the taught-path FILE")
        return {"cmd": "replay", "file": os.path.abspath(args.file)}
    if mode == "drag" and args.record is not None:
        req = {"cmd": "mode", "mode": "drag", "record": os.path.abspath(args.record)}
        return {**req, "force": True} if args.force else req
    if mode == "move" and args.joints is not None:
        q = parse_joints(args.joints, degrees=args.degrees)
        # a non-finite value goes as its word: the service names the joint (JSON has no NaN)
        return {"cmd": "move_joints", "q": [float(v) if math.isfinite(v) else str(v) for v in q]}
    return {"cmd": "mode", "mode": mode}


def run(args: argparse.Namespace) -> int:
    return answer(request(args.socket, request_of(args)))
