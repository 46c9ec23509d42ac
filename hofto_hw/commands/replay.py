"""``hofto-hw replay PARAMS FILE`` (or ``hofto-hw replay FLIGHT.mcap``): run an observer
offline over a recording, apply the collision thresholds, list contact episodes, optionally
write a PNG and JSON.

Example (UR10e; config, column map and thresholds are found from the parameters file)::

    hofto-hw replay configs/ur10e/parameters.yaml ur-20_01_22-push_pose_1.csv --plot push.png

A flight-recorder log carries its config, parameters and thresholds: ``hofto-hw replay
run.mcap`` re-runs its observers and monitor and checks the recorded collision tick
(hofto_hw/commands/replay_flight.py; exit 1 when the replay decides differently).
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from pathlib import Path

from hofto_hw.commands.args import (
    add_config,
    add_recording_options,
    finite_nonnegative_float,
    output_file,
    parse_rows,
    refuse_overwrite,
)
from hofto_hw.errors import UserError
from hofto_hw.replay.defaults import OBSERVER_NAMES

DEFAULT_OBSERVER = "momentum"


def progress_for(label: str) -> Callable[[str], Callable[[int, int], None]]:
    """Progress callbacks per stage of a long replay (``label: stage: k/N``, on stderr)."""
    from hofto_hw.progress import Progress

    def stage(name: str) -> Callable[[int, int], None]:
        bar: Progress | None = None

        def update(done: int, total: int) -> None:
            nonlocal bar
            if bar is None:
                bar = Progress(f"{label}: {name}", total)
            bar.update(done)

        return update

    return stage


def add_common(parser: argparse.ArgumentParser) -> None:
    """Options shared by replay and thresholds."""
    add_config(parser, default=None)
    add_recording_options(parser, "rows (1-based, inclusive) to replay")


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "params",
        type=Path,
        metavar="PARAMS",
        help="identified-parameters file (omit for a flight-recorder log: it carries its own)",
    )
    parser.add_argument(
        "file", type=Path, nargs="?", metavar="FILE", help="recording (CSV or .mcap)"
    )
    add_common(parser)
    parser.add_argument(
        "--reproduce",
        action="store_true",
        help="flight-recorder logs (the default for them): re-run the recorded observers and "
        "monitor and check the recorded collision tick; exit 1 if it differs",
    )
    parser.add_argument(
        "--observer",
        choices=OBSERVER_NAMES,
        default=DEFAULT_OBSERVER,
        help=f"observer to run (default: {DEFAULT_OBSERVER})",
    )
    parser.add_argument(
        "--thresholds", type=Path, help="thresholds file (default: <robot>/thresholds.yaml)"
    )
    parser.add_argument(
        "--no-thresholds", action="store_true", help="estimate statistics only, no detection"
    )
    parser.add_argument(
        "--merge-gap",
        type=finite_nonnegative_float,
        default=0.5,
        help="join episodes closer than this [s]",
    )
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    parser.add_argument("--plot", type=output_file, metavar="PNG", help="write a figure")


def _print_text(report_dict: dict, thresholds: Path | None) -> None:
    d = report_dict
    print(f"{d['file']}: {d['samples']} samples, {d['duration']:.2f} s, observer {d['observer']}")
    for note in d["notes"]:
        print(f"  note: {note}")
    print(
        "  joint   mean[N·m]   std[N·m]  max|.|[N·m]" + ("  max ratio" if d["thresholds"] else "")
    )
    for row in d["joints"]:
        line = f"  {row['joint']:5d} {row['mean']:11.2f} {row['std']:10.2f} {row['max_abs']:12.2f}"
        if "max_ratio" in row:
            line += f" {row['max_ratio']:10.2f}"
        print(line)
    if not d["thresholds"]:
        print(
            "  no thresholds for this observer: statistics only (calibrate with "
            "`hofto-hw thresholds calibrate`)"
        )
        return
    print(f"  thresholds: {thresholds}")
    print(f"  {len(d['episodes'])} contact episode(s)")
    for i, ep in enumerate(d["episodes"], start=1):
        j = max(ep["joints"], key=lambda jj: ep["peak"][jj - 1])
        print(
            f"  {i:3d}. {ep['start']:.3f}-{ep['end']:.3f} s ({ep['duration']:.2f} s, rows "
            f"{ep['rows'][0]}-{ep['rows'][1]}), joints {','.join(map(str, ep['joints']))}, "
            f"peak {ep['peak'][j - 1]:.1f} N·m on joint {j}, {ep['peak_ratio']:.2f}x threshold"
        )


def run(args: argparse.Namespace) -> int:
    from hofto_hw.replay.flight_log import flight_metadata

    if args.file is None:  # `replay FILE`: only a flight log carries its own parameters
        args.file, args.params = args.params, None
    if flight_metadata(args.file) is not None:
        if args.params is not None:
            raise UserError(
                f"{args.file}: a flight-recorder log carries its config and parameters; "
                "run `hofto-hw replay FILE` without PARAMS"
            )
        from hofto_hw.commands.replay_flight import run_flight

        return run_flight(args)
    if args.params is None:
        raise UserError(f"{args.file}: not a flight-recorder log: give PARAMS FILE")
    if args.reproduce:
        raise UserError(f"{args.file}: --reproduce needs a flight-recorder log")
    from hofto_hw.commands.backend import observer_backend
    from hofto_hw.replay.plot import plot_replay
    from hofto_hw.replay.session import load_for_replay, run_replay
    from hofto_hw.replay.setup import (
        default_thresholds,
        load_setup,
        load_thresholds_for,
        sha256_of,
    )

    refuse_overwrite(args.plot, [args.params, args.file, args.config, args.thresholds], "--plot")
    setup = load_setup(args.params, args.config)
    th_path = args.thresholds if args.thresholds is not None else default_thresholds(setup)
    if args.no_thresholds:
        th_path = None
    thresholds = load_thresholds_for(setup, th_path) if th_path is not None else None
    if thresholds is not None and args.observer not in thresholds.observers:
        raise UserError(
            f"{th_path}: no thresholds for observer {args.observer!r} (has: "
            f"{', '.join(thresholds.observers)}); calibrate it or choose another --observer"
        )
    rec = load_for_replay(
        setup,
        args.file,
        args.columns,
        parse_rows(args.rows),
        "drop" if args.drop_bad_rows else None,
        progress_for(args.file.name),
    )
    report = run_replay(
        setup,
        rec,
        args.observer,
        thresholds,
        args.merge_gap,
        progress_for(args.file.name),
        backend=observer_backend(),
    )
    d = report.as_dict()
    if thresholds is not None and thresholds.parameters is not None:
        ref = thresholds.parameters
        if ref.sha256 and ref.sha256 != sha256_of(args.params):
            d["notes"].append(
                f"thresholds were calibrated with another parameters file ({ref.file}); "
                f"recalibrate for {args.params.name}"
            )
    if args.plot is not None:
        d["plot"] = str(args.plot)
    # results first: a figure that cannot be written must not cost the user the numbers
    if args.json:
        print(json.dumps(d, indent=2), flush=True)
    else:
        _print_text(d, th_path)
    if args.plot is not None:
        plot_replay(report.result, report.episodes, args.plot)
        if not args.json:
            print(f"  plot: {args.plot}")
    return 0
