"""``hofto-hw replay FILE`` for flight-recorder logs: reproduce the run's collision decision.

Prints the recorded and the replayed first collision (tick, joints) and each observer's
largest difference from its recorded estimate; exit code 0 when they match, 1 when not.
``--plot PNG``: the detector observer's recorded and replayed estimate per joint.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from hofto_hw.replay.flight_log import FlightLog
    from hofto_hw.replay.reproduce import Reproduction


def run_flight(args: argparse.Namespace) -> int:
    from hofto_hw.commands.args import refuse_overwrite
    from hofto_hw.replay.flight_log import read_flight_log
    from hofto_hw.replay.reproduce import reproduce

    plot = getattr(args, "plot", None)
    refuse_overwrite(plot, [args.file], "--plot")
    log = read_flight_log(args.file)
    result = reproduce(log)
    d = {
        "file": str(args.file),
        "ticks": log.n_ticks,
        "duration": float(log.t[-1] - log.t[0]),
        "robot": log.metadata.get("robot", ""),
        **result.as_dict(),
    }
    if plot is not None:
        d["plot"] = str(plot)
    if args.json:
        print(json.dumps(d, indent=2), flush=True)
        _plot(plot, log, result)
        return 0 if result.match else 1
    print(
        f"{d['file']}: flight log, robot {d['robot']}, {d['ticks']} ticks, "
        f"{d['duration']:.3f} s, detector {result.detector}"
    )
    for name, diff in result.max_abs_diff.items():
        exact = " (bit-exact)" if diff == 0.0 else ""
        print(f"  observer {name}: max |replayed - recorded| = {diff:.3g} N·m{exact}")
    rec = result.recorded
    recorded = "none" if rec is None else f"tick {rec.tick} (t {rec.t:.3f} s), joint {rec.joint}"
    replayed = (
        "none"
        if result.replayed_tick is None
        else f"tick {result.replayed_tick}, joints {result.replayed_joints}"
    )
    print(f"  recorded collision: {recorded}")
    print(f"  replayed collision: {replayed}")
    print("  MATCH" if result.match else "  MISMATCH: the replay decides differently")
    sys.stdout.flush()
    if _plot(plot, log, result):
        print(f"  plot: {plot}")
    return 0 if result.match else 1


def _plot(path: Path | None, log: FlightLog, result: Reproduction) -> bool:
    """Write the figure after the results (a figure that cannot be written must not cost
    the user the numbers); False when no --plot."""
    if path is None:
        return False
    from hofto_hw.replay.run_plot import replay_figure, save_figure

    save_figure(replay_figure(log, result.replayed, result.detector, result.replayed_tick), path)
    return True
