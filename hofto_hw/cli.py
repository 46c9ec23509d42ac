"""The ``hofto-hw`` command.

Each sub-command lives in its own module (``hofto_hw/commands/<name>.py`` or, for driver
tools, under ``drivers/``) exposing two functions:

- ``configure(parser: argparse.ArgumentParser) -> None`` adds its arguments;
- ``run(args: argparse.Namespace) -> int`` does the work and returns the exit code.

Modules are imported only when their command runs, so ``hofto-hw config check`` does not pay
for pinocchio or pysoem. User errors are raised as :class:`hofto_hw.errors.UserError` and
printed as one clear line (no traceback), exit code 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from hofto_hw.errors import UserError

#: command name -> (module path, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": (
        "hofto_hw.commands.demo",
        "run the paper's Table II experiment on the simulated arm",
    ),
    "config": ("hofto_hw.commands.config", "print the config JSON schema or check a file"),
    "excite": ("hofto_hw.commands.excite", "design an optimized excitation trajectory"),
    "identify": ("hofto_hw.commands.identify", "identify dynamic parameters from a recording"),
    "validate": ("hofto_hw.commands.validate", "check identified parameters on recordings"),
    "replay": ("hofto_hw.commands.replay", "run observers and collision thresholds offline"),
    "thresholds": ("hofto_hw.commands.thresholds", "calibrate collision thresholds"),
    "tune": ("hofto_hw.commands.tune", "tune observer gain and thresholds with injected contacts"),
    "payload": ("hofto_hw.commands.payload", "identify a payload (tool or load) from recordings"),
    "sim-ethercat": (
        "drivers.sim.ethercat_cli",
        "serve emulated EtherCAT CiA-402 drives on a network interface",
    ),
}


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """Build the argument parser; with ``only`` set, import just that command's module."""
    parser = argparse.ArgumentParser(
        prog="hofto-hw",
        description="Sensorless interaction-force estimation for six-axis servo arms.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module_path, help_text) in COMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
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
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    if getattr(args, "_missing", None):
        print(f"hofto-hw {args.command}: not available in this build", file=sys.stderr)
        return 2
    try:
        return int(args._run(args) or 0)
    except UserError as exc:
        print(f"hofto-hw {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
