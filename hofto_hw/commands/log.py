"""``hofto-hw log info FILE`` and ``hofto-hw log recover FILE [-o OUT]``: inspect flight-
recorder MCAP logs and salvage one whose writer was killed.

Examples::

    hofto-hw log info /var/log/hofto-hw/run.mcap
    hofto-hw log recover /var/log/hofto-hw/run.mcap        # -> run.recovered.mcap
    hofto-hw log plot /var/log/hofto-hw/run.mcap           # -> run.png
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from hofto_hw.commands.args import output_file, refuse_overwrite
from hofto_hw.errors import UserError


def configure(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="log_command", metavar="ACTION", required=True)
    p = sub.add_parser("info", help="topics, message counts, duration, size of a log")
    p.add_argument("file", type=Path, metavar="FILE")
    p.add_argument("--json", action="store_true", help="print as JSON")
    p = sub.add_parser("recover", help="rewrite a truncated log into a complete one")
    p.add_argument("file", type=Path, metavar="FILE")
    p.add_argument(
        "-o", "--output", type=Path, help="output file (default: FILE's stem + .recovered.mcap)"
    )
    p = sub.add_parser(
        "plot", help="a picture of a run: joints, torques vs thresholds, stop, drag, timing"
    )
    p.add_argument("file", type=Path, metavar="FILE")
    p.add_argument(
        "-o", "--output", type=output_file, metavar="PNG", help="default: FILE's stem + .png"
    )


def run(args: argparse.Namespace) -> int:
    if args.log_command == "info":
        return _info(args)
    if args.log_command == "plot":
        return _plot(args)
    return _recover(args)


def _plot(args: argparse.Namespace) -> int:
    from hofto_hw.recording.recover import check_magic
    from hofto_hw.replay.flight_log import read_flight_log
    from hofto_hw.replay.run_plot import run_figure, save_figure

    src: Path = args.file
    check_magic(src)  # a missing or non-MCAP input is said before anything else
    dst: Path = args.output if args.output is not None else src.with_suffix(".png")
    if args.output is None:
        if dst.exists():
            raise UserError(f"{dst}: exists; name the output with -o (it will be replaced)")
        try:
            output_file(str(dst))
        except argparse.ArgumentTypeError as exc:
            raise UserError(f"-o: {exc}") from None
    refuse_overwrite(dst, [src], "-o")
    save_figure(run_figure(read_flight_log(src)), dst)
    print(f"{src}: wrote {dst}")
    return 0


def _info(args: argparse.Namespace) -> int:
    from hofto_hw.recording.info import log_info

    info = log_info(args.file)
    if args.json:
        print(json.dumps(info.as_dict(), indent=2))
        return 0
    state = "complete" if info.complete else "INCOMPLETE (truncated; try `hofto-hw log recover`)"
    print(f"{info.path}: {info.size / 1e6:.2f} MB, {info.duration:.3f} s, {state}")
    width = max((len(t) for t in info.topics), default=0)
    for topic, (type_name, count) in sorted(info.topics.items()):
        print(f"  {topic:<{width}}  {count:9d}  {type_name}")
    if info.attachments:
        print(f"  attachments: {', '.join(info.attachments)}")
    for name, meta in info.metadata.items():
        print(f"  metadata {name}: {', '.join(f'{k}={v}' for k, v in meta.items())}")
    return 0


def _recover(args: argparse.Namespace) -> int:
    from hofto_hw.outputs import output_problem
    from hofto_hw.recording.recover import check_magic, default_output, recover

    src: Path = args.file
    dst: Path = args.output if args.output is not None else default_output(src)
    if args.output is None and dst.exists():
        raise UserError(f"{dst}: exists; name the output with -o (it will be replaced)")
    check_magic(src)  # the input first: a wrong file is the likelier mistake
    problem = output_problem(dst)
    if problem is None and dst.exists() and os.path.samefile(src, dst):
        problem = "is the input; name another output"
    if problem is not None:
        option = "-o " if args.output is not None else "output (FILE's stem + .recovered.mcap) "
        raise UserError(f"{option}{dst}: {problem}")
    out = recover(src, dst)
    from hofto_hw.recording.shared import remove_stale

    for name, size, pid in remove_stale():  # what a killed run left besides its log
        print(f"removed stale shared memory /dev/shm/{name} ({size / 1e6:.1f} MB, pid {pid} gone)")
    state = "was complete" if out.complete else f"truncated ({out.stopped or 'end of file'})"
    print(
        f"{src}: {state}; wrote {dst}: {out.total} messages up to {out.end_ns * 1e-9:.3f} s, "
        f"{out.attachments} attachments, {out.metadata} metadata records"
    )
    for topic, n in sorted(out.messages.items()):
        print(f"  {topic}: {n}")
    return 0
