"""``hofto-hw replay FILE`` for flight-recorder logs: reproduce the run's collision decision.

Prints the recorded and the replayed first collision (tick, joints) and each observer's
largest difference from its recorded estimate; exit code 0 when they match, 1 when not.
"""

from __future__ import annotations

import argparse
import json


def run_flight(args: argparse.Namespace) -> int:
    from hofto_hw.replay.flight_log import read_flight_log
    from hofto_hw.replay.reproduce import reproduce

    log = read_flight_log(args.file)
    result = reproduce(log)
    d = {
        "file": str(args.file),
        "ticks": log.n_ticks,
        "duration": float(log.t[-1] - log.t[0]),
        "robot": log.metadata.get("robot", ""),
        **result.as_dict(),
    }
    if args.json:
        print(json.dumps(d, indent=2))
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
    return 0 if result.match else 1
