"""The ``hofto-hw`` command.

Each sub-command lives in its own module (``hofto_hw/commands/<name>.py``) exposing two
functions:

- ``configure(parser: argparse.ArgumentParser) -> None`` adds its arguments;
- ``run(args: argparse.Namespace) -> int`` does the work and returns the exit code.

Modules are imported only when their command runs, so ``hofto-hw config check`` does not pay
for pinocchio or pysoem. User errors are raised as :class:`hofto_hw.errors.UserError` and
printed as one clear line (no traceback), exit code 2.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Sequence
from typing import NoReturn

from hofto_hw.errors import UserError

#: command name -> (module path, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": (
        "hofto_hw.commands.demo",
        "run the paper's Table II experiment on the simulated arm",
    ),
    "run": ("hofto_hw.commands.run", "run the real-time loop (simulated arm by default)"),
    "status": ("hofto_hw.commands.status", "state, faults and timing of the running service"),
    "reset": ("hofto_hw.commands.reset", "reset the service's latched faults"),
    "stop": ("hofto_hw.commands.stop", "stop the arm (the service keeps running)"),
    "mode": ("hofto_hw.commands.mode", "set the service's controller mode (hold, move, drag)"),
    "enable": ("hofto_hw.commands.enable", "hold (on) or release (off) the drag enabling input"),
    "config": ("hofto_hw.commands.config", "print the config JSON schema or check a file"),
    "excite": ("hofto_hw.commands.excite", "design an optimized excitation trajectory"),
    "identify": ("hofto_hw.commands.identify", "identify dynamic parameters from a recording"),
    "validate": ("hofto_hw.commands.validate", "check identified parameters on recordings"),
    "replay": ("hofto_hw.commands.replay", "run observers and collision thresholds offline"),
    "thresholds": ("hofto_hw.commands.thresholds", "calibrate collision thresholds"),
    "log": ("hofto_hw.commands.log", "inspect flight-recorder logs or recover a truncated one"),
    "tune": ("hofto_hw.commands.tune", "tune observer gain and thresholds with injected contacts"),
    "payload": ("hofto_hw.commands.payload", "identify a payload (tool or load) from recordings"),
    "brake": ("hofto_hw.commands.brake", "test the holding brakes (offline)"),
    "home": (
        "hofto_hw.commands.home",
        "home the incremental axes (CiA 402; via the service if one runs)",
    ),
    "zero": (
        "hofto_hw.commands.zero",
        "re-zero a joint at a reference (via the service if one runs)",
    ),
    "sim-ethercat": (
        "hofto_hw.commands.sim_ethercat",
        "serve emulated EtherCAT CiA-402 drives on a network interface",
    ),
    "sim-canopen": ("hofto_hw.commands.sim_canopen", "serve emulated CANopen CiA-402 drives"),
    "drive": ("hofto_hw.commands.drive", "drive profiles: import a vendor ESI/EDS file"),
    "bus": ("hofto_hw.commands.bus", "the live bus: scan it into draft drive profiles"),
}


class Parser(argparse.ArgumentParser):
    """argparse with a one-line error (``hofto-hw CMD: error: ...``, exit code 2)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """Build the argument parser; with ``only`` set, import just that command's module."""
    from hofto_hw.commands.args import HelpFormatter

    parser = Parser(
        prog="hofto-hw",
        description="Sensorless interaction-force estimation for six-axis servo arms.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module_path, help_text) in COMMANDS.items():
        p = sub.add_parser(
            name, help=help_text, description=help_text, formatter_class=HelpFormatter
        )
        if only is None or name == only:
            try:
                module = importlib.import_module(module_path)
            except ModuleNotFoundError as exc:
                if exc.name != module_path:
                    raise
                p.set_defaults(_missing=module_path)
                continue
            module.configure(p)
            p.set_defaults(_run=module.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``hofto-hw`` console script."""
    argv = list(sys.argv[1:] if argv is None else argv)
    first = next((a for a in argv if not a.startswith("-")), None)
    parser = build_parser(only=first if first in COMMANDS else None)
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, or a bad argument (already printed, one line)
        return exc.code if isinstance(exc.code, int) else 2
    if args.command is None:
        parser.print_help()
        return 2
    if getattr(args, "_missing", None):
        print(f"hofto-hw {args.command}: not available in this build", file=sys.stderr)
        return 2
    try:
        code = int(args._run(args) or 0)
        sys.stdout.flush()  # a closed pipe shows here, not in the interpreter's exit
        return code
    except UserError as exc:
        print(f"hofto-hw {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        return _quiet_broken_pipe()


def _quiet_broken_pipe() -> int:
    """The reader of stdout went away (``hofto-hw config schema | head``): exit quietly as
    standard tools do. stdout is pointed at /dev/null so the interpreter's final flush of
    the buffered rest does not fail again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass
    return 141  # 128 + SIGPIPE, what a shell reports for a tool killed by the signal


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
