"""Argument types and option groups shared by the ``hofto-hw`` commands.

Types raise :class:`argparse.ArgumentTypeError`, which the CLI prints as one line naming the
option and the value (exit code 2), before any work is done.

Output files: the user names a file; its folder must exist (nothing is created that the user
did not name: a typo in a folder name would otherwise scatter files), it must not be a
folder, and it must not be one of the command's inputs (:func:`refuse_overwrite`). Defaults
under ``out/`` are ours, so that folder is created (:func:`ensure_default_folder`).
"""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from hofto_hw.errors import UserError
from hofto_hw.outputs import output_problem


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows ``(default: X)`` for every option that has a default worth showing."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        if "default" in text or action.default in (None, False, argparse.SUPPRESS):
            return text
        if isinstance(action.default, list | tuple) and not action.default:
            return text
        return super()._get_help_string(action)


def finite_float(text: str) -> float:
    """A finite number (no nan, inf)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def finite_positive_float(text: str) -> float:
    """A finite number > 0 (durations, periods, rates, cut-offs)."""
    value = finite_float(text)
    if not value > 0.0:
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text!r}")
    return value


def run_seconds(text: str) -> float:
    """How long a server runs (the emulators' ``--duration``): a finite number of seconds
    > 0; nan, inf, 0 and negative values are refused naming the value."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0.0):
        raise argparse.ArgumentTypeError(
            f"must be a finite number of seconds > 0, got {text!r} (not a positive finite number)"
        )
    return value


def finite_nonnegative_float(text: str) -> float:
    """A finite number >= 0 (margins, gaps)."""
    value = finite_float(text)
    if value < 0.0:
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0, got {text!r}")
    return value


def positive_int(text: str) -> int:
    """An integer >= 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text!r}")
    return value


def at_most(
    high: float, kind: Callable[[str], Any] = finite_positive_float, unit: str = ""
) -> Callable[[str], Any]:
    """``kind`` (a type above) with an upper bound ``high``: for numbers whose bound exists by
    design (a fraction of a limit, a sample rate, the size of what gets allocated)."""

    def parse(text: str) -> Any:
        value = kind(text)
        if value > high:
            raise argparse.ArgumentTypeError(f"at most {high:g}{unit}, got {text!r}")
        return value

    parse.__name__ = kind.__name__  # argparse names the type in "invalid ... value"
    return parse


def parse_rows(text: str | None, what: str = "--rows") -> tuple[int, int] | None:
    """``'FIRST:LAST'`` (1-based, inclusive) -> (first, last); None passes through."""
    if text is None:
        return None
    try:
        a, b = (int(x) for x in text.split(":"))
    except ValueError:
        raise UserError(
            f"{what}: expected FIRST:LAST (1-based rows, e.g. 635:3510), got {text!r}"
        ) from None
    if not 1 <= a <= b:
        raise UserError(f"{what}: need 1 <= FIRST <= LAST, got {text!r}")
    return a, b


def output_file(text: str) -> Path:
    """A file to write: not a folder, in an existing folder that takes a new file
    (:func:`hofto_hw.outputs.output_problem`, checked when the arguments are parsed)."""
    problem = output_problem(text)
    if problem is not None:
        sep = " " if problem.startswith("is a folder") else ": "
        raise argparse.ArgumentTypeError(f"{text!r}{sep}{problem}")
    return Path(text)


def ensure_default_folder(path: Path) -> None:
    """Create the folder of one of our default outputs (``out/``); a failure is a UserError."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"{path}: cannot create folder {path.parent}: {exc.strerror}") from None
    if path.is_dir():
        raise UserError(f"{path}: is a folder; pass --plot FILE")


def refuse_overwrite(output: Path | None, inputs: Iterable[Path | str | None], option: str) -> None:
    """Refuse an ``output`` that is (the same file as) one of ``inputs``."""
    if output is None or not output.exists():
        return
    for item in inputs:
        if item is None:
            continue
        src = Path(str(item).rsplit("@", 1)[0]) if "@" in str(item) else Path(item)
        if src.exists() and os.path.samefile(src, output):
            raise UserError(
                f"{option} {output}: is an input of this command; refusing to overwrite"
            )


def write_failed(path: Path, what: str, exc: OSError) -> UserError:
    """The one-line error for a write that failed after the work was done."""
    return UserError(f"{path}: cannot write {what}: {exc.strerror or exc}")


def add_config(
    parser: argparse.ArgumentParser, default: str | None, required: bool = False
) -> None:
    """``--config PATH|ROBOT``: a config file or a robot name (configs/<name>.yaml)."""
    parser.add_argument(
        "--config",
        metavar="PATH|ROBOT",
        default=default,
        required=required,
        help="system config: a YAML file or a robot name (configs/<ROBOT>.yaml)"
        + ("" if default is not None or required else "; default: found by robot name"),
    )


def add_recording_options(parser: argparse.ArgumentParser, rows_help: str) -> None:
    """``--columns``, ``--rows`` and ``--drop-bad-rows`` of every command reading recordings."""
    parser.add_argument("--columns", type=Path, help="CSV column map (default: found by width)")
    parser.add_argument("--rows", metavar="FIRST:LAST", help=rows_help)
    parser.add_argument(
        "--drop-bad-rows",
        action="store_true",
        help="drop corrupt CSV rows with a warning instead of refusing the file",
    )
