"""``hofto-hw thresholds``: calibrate collision thresholds on free-motion recordings, and
check them on other recordings (leave-some-out: no alarm may be raised on free motion).

Examples (UR10e)::

    hofto-hw thresholds calibrate --params configs/ur10e/parameters.yaml \\
        -o configs/ur10e/thresholds.yaml RUN1.csv RUN2.csv ...
    hofto-hw thresholds check --params configs/ur10e/parameters.yaml OTHER1.csv OTHER2.csv
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import math
from pathlib import Path

from hofto_hw.commands.args import (
    HelpFormatter,
    finite_nonnegative_float,
    finite_positive_float,
    output_file,
    parse_rows,
    refuse_overwrite,
    write_failed,
)
from hofto_hw.commands.replay import add_common, progress_for
from hofto_hw.errors import UserError
from hofto_hw.replay.defaults import OBSERVER_NAMES

CALIBRATED_BY_DEFAULT = ("momentum", "hofto", "dob", "eso", "direct")


def configure(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    cal = sub.add_parser(
        "calibrate", help="thresholds from free-motion recordings", formatter_class=HelpFormatter
    )
    cal.add_argument("files", nargs="+", type=Path, metavar="FILE")
    cal.add_argument("-o", "--output", type=output_file, required=True, help="thresholds file")
    cal.add_argument("--params", type=Path, required=True, help="identified-parameters file")
    cal.add_argument(
        "--observer",
        action="append",
        choices=OBSERVER_NAMES,
        help=f"observer(s) to calibrate (repeat; default: {', '.join(CALIBRATED_BY_DEFAULT)})",
    )
    cal.add_argument(
        "--margin",
        type=finite_nonnegative_float,
        default=0.6,
        help="thresholds = (1 + margin) x the smallest envelope of the residuals (default 0.6)",
    )
    cal.add_argument(
        "--debounce",
        type=finite_positive_float,
        default=0.03,
        help="time above threshold to trip [s]",
    )
    cal.add_argument(
        "--standstill",
        action="store_true",
        help="fit a standstill term separate from the reversal term (held friction at rest)",
    )
    cal.add_argument(
        "--standstill-time",
        type=float,
        default=0.0,
        help="time constant [s] with which the standstill indicator rises after a stop",
    )
    cal.add_argument(
        "--sustained",
        action="store_true",
        help="fit the residuals sustained over the debounce time, not single-sample peaks",
    )
    cal.add_argument("--json", action="store_true", help="print a summary as JSON")
    add_common(cal)
    chk = sub.add_parser(
        "check", help="replay recordings and count alarms per file", formatter_class=HelpFormatter
    )
    chk.add_argument("files", nargs="+", type=Path, metavar="FILE")
    chk.add_argument("--params", type=Path, required=True, help="identified-parameters file")
    chk.add_argument("--thresholds", type=Path, help="default: <robot>/thresholds.yaml")
    chk.add_argument(
        "--observer",
        action="append",
        choices=OBSERVER_NAMES,
        help="observer(s) to check (repeat; default: all in the thresholds file)",
    )
    chk.add_argument("--json", action="store_true", help="print the results as JSON")
    add_common(chk)


def _calibrate(args: argparse.Namespace) -> int:
    from hofto_hw.commands.backend import observer_backend
    from hofto_hw.config.collision import CollisionConfig
    from hofto_hw.replay.calibrate import calibrate
    from hofto_hw.replay.runner import run_observer
    from hofto_hw.replay.session import load_for_replay, observer_for
    from hofto_hw.replay.setup import load_setup, observer_config, sha256_of
    from hofto_hw.replay.thresholds import (
        ObserverThresholds,
        ParametersRef,
        ThresholdsFile,
        write_thresholds,
    )

    inputs = [args.params, args.config, args.columns, *args.files]
    refuse_overwrite(args.output, inputs, "--output")
    setup = load_setup(args.params, args.config)
    n = setup.model.n
    bad = "drop" if args.drop_bad_rows else None
    rows = parse_rows(args.rows)
    recs = [
        load_for_replay(setup, f, args.columns, rows, bad, progress_for(f.name)) for f in args.files
    ]
    if not (math.isfinite(args.standstill_time) and args.standstill_time >= 0.0):
        raise UserError(f"--standstill-time must be >= 0 s, got {args.standstill_time}")
    template = CollisionConfig(
        base=[1.0] * n, debounce_time=args.debounce, standstill_time=args.standstill_time
    )
    entries: dict[str, ObserverThresholds] = {}
    for name in args.observer or CALIBRATED_BY_DEFAULT:
        obs_cfg = observer_config(name, setup)
        residuals = [
            run_observer(
                rec,
                observer_for(name, obs_cfg, setup, rec, observer_backend()),
                progress=progress_for(Path(rec.source).name)(name),
            )
            for rec in recs
        ]
        cal = calibrate(
            recs,
            residuals,
            template,
            margin=args.margin,
            terms=(True, True, True, True, args.standstill),
            sustain=args.sustained,
        )
        entries[name] = ObserverThresholds(
            observer=obs_cfg, monitor=cal.config, peak=list(cal.peak), samples=cal.samples
        )
    content = ThresholdsFile(
        robot=setup.config.robot.name,
        parameters=ParametersRef(file=args.params.name, sha256=sha256_of(args.params)),
        created=_dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        margin=args.margin,
        calibrated_on=[f.name for f in args.files],
        observers=entries,
    )
    try:
        write_thresholds(args.output, content)
    except OSError as exc:
        raise write_failed(args.output, "thresholds file", exc) from None
    summary = {
        name: {"base": e.monitor.base, "peak": e.peak, "samples": e.samples}
        for name, e in entries.items()
    }
    if args.json:
        print(json.dumps({"output": str(args.output), "observers": summary}, indent=2))
    else:
        print(f"{args.output}: thresholds for {', '.join(entries)} from {len(recs)} recording(s)")
        for name, s in summary.items():
            base = " ".join(f"{v:6.2f}" for v in s["base"])
            print(f"  {name:9s} resting thresholds [N·m]: {base}")
    return 0


def _check(args: argparse.Namespace) -> int:
    from hofto_hw.replay.session import load_for_replay, run_replay
    from hofto_hw.replay.setup import default_thresholds, load_setup, load_thresholds_for

    setup = load_setup(args.params, args.config)
    th_path = args.thresholds or default_thresholds(setup)
    if th_path is None:
        raise UserError(f"no thresholds file: pass --thresholds (looked in {setup.robot_dir})")
    thresholds = load_thresholds_for(setup, th_path)
    names = args.observer or list(thresholds.observers)
    for name in names:
        if name not in thresholds.observers:
            raise UserError(f"{th_path}: no thresholds for observer {name!r}")
    bad = "drop" if args.drop_bad_rows else None
    results = []
    for f in args.files:
        rec = load_for_replay(
            setup, f, args.columns, parse_rows(args.rows), bad, progress_for(f.name)
        )
        for name in names:
            rep = run_replay(setup, rec, name, thresholds, progress=progress_for(f.name))
            worst = max(row.get("max_ratio", 0.0) for row in rep.stats())
            results.append(
                {
                    "file": str(f),
                    "observer": name,
                    "episodes": [ep.as_dict() for ep in rep.episodes],
                    "max_ratio": worst,
                }
            )
    if args.json:
        print(json.dumps(results, indent=2))
    else:
        for r in results:
            starts = ", ".join(f"{ep['start']:.2f}" for ep in r["episodes"][:6])
            print(
                f"{Path(r['file']).name:40s} {r['observer']:9s} {len(r['episodes']):3d} episode(s)"
                f"  max |est|/threshold {r['max_ratio']:.2f}" + (f"  at {starts}" if starts else "")
            )
    return 0


def run(args: argparse.Namespace) -> int:
    if args.action == "calibrate":
        return _calibrate(args)
    return _check(args)
