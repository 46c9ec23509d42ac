"""Sensitivity to synthetic contacts injected into contact-free recordings (issue 11).

For each observer named in the thresholds file: the observer runs over each recording, the
collision monitor (safety.collision, the thresholds file's settings) over its estimate; false
alarms are the joints that trip without any pulse. Then, per amplitude and round, a train of
half-sine pulses (one joint at a time, random sign, ``--width`` s) is subtracted from the
measured torque with the motion kept, the observer re-runs, and each pulse counts as found
if its joint trips (monitor's debounce) within the pulse + 0.2 s
(hofto_hw.replay.pulses). A pulse is *at rest* when no joint moved during it.

Prints per observer and joint, in motion and at rest: the detection rate per amplitude, the
median delay, and the smallest amplitude found in at least ``--found`` of the tries with 0
false alarms on that joint (">A" when even the largest is not); ``--json`` for figures.

    python tools/pulse_detection.py PARAMS THRESHOLDS FILE... [--observer momentum]
        [--amplitudes 2,3,5,7,10,15,20,30] [--rounds 2] [--json]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from hofto_hw.commands.backend import observer_backend
from hofto_hw.replay.pulses import STATES, PulseStats, score, tally
from hofto_hw.replay.runner import run_monitor
from hofto_hw.replay.session import load_for_replay, observer_for
from hofto_hw.replay.setup import load_setup, load_thresholds_for, observer_config
from hofto_hw.replay.tuning import pulsed_runs
from safety.collision import CollisionMonitor


def smallest_found(stats: PulseStats, false: np.ndarray, found: float) -> list[list[float | None]]:
    """Per state (motion, rest) and joint: the smallest amplitude whose detection rate is >=
    ``found`` (and every larger one too), None when none is or the joint has false alarms;
    NaN where no pulse was tried."""
    amps = stats.amplitudes
    rate = stats.rate
    out: list[list[float | None]] = []
    for s in range(len(STATES)):
        row: list[float | None] = []
        for j in range(rate.shape[2]):
            r = rate[:, s, j]
            if np.all(np.isnan(r)):
                row.append(float("nan"))
                continue
            best = None
            for a in range(len(amps) - 1, -1, -1):
                if np.isnan(r[a]) or r[a] < found:
                    break
                best = amps[a]
            row.append(None if false[j] else best)
        out.append(row)
    return out


def measure(args: argparse.Namespace, name: str, setup, th, recs) -> dict:
    obs_cfg = observer_config(name, setup, th)
    mcfg = th.observers[name].monitor
    backend = observer_backend()
    runs = pulsed_runs(
        recs,
        lambda r: observer_for(name, obs_cfg, setup, r, backend),
        args.amps,
        args.width,
        args.rounds,
        args.seed,
    )
    n = setup.model.n
    stats = PulseStats.empty(args.amps, n)
    false = np.zeros(n, dtype=int)
    per_file = {}
    for run in runs:
        thr, joints, _ = run_monitor(run.rec, run.est, CollisionMonitor(mcfg))
        tripped = joints.any(axis=0)
        false += tripped
        per_file[Path(run.rec.source).name] = [int(j) + 1 for j in np.flatnonzero(tripped)]
        for a, rounds in enumerate(run.pulsed):
            for est, pulses in rounds:
                tally(stats, a, pulses, score(pulses, est, thr, run.rec.t, mcfg.debounce_time))
    rate = stats.rate
    delay = stats.median_delay()
    nan = lambda x: None if x is None or np.isnan(x) else float(x)  # noqa: E731
    return {
        "observer": name,
        "false_alarm_joints": per_file,
        "false_alarms": false.tolist(),
        "rate": {
            st: {f"{a:g}": [nan(v) for v in rate[i, s]] for i, a in enumerate(args.amps)}
            for s, st in enumerate(STATES)
        },
        "tries": {
            st: {f"{a:g}": stats.tries[i, s].astype(int).tolist() for i, a in enumerate(args.amps)}
            for s, st in enumerate(STATES)
        },
        "median_delay": {
            st: {f"{a:g}": [nan(v) for v in delay[i, s]] for i, a in enumerate(args.amps)}
            for s, st in enumerate(STATES)
        },
        "smallest_found": {
            st: [v if v is None or not np.isnan(v) else "untried" for v in row]
            for st, row in zip(STATES, smallest_found(stats, false, args.found), strict=True)
        },
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("params")
    ap.add_argument("thresholds")
    ap.add_argument("files", nargs="+")
    ap.add_argument("--config", help="robot config (default: found from the parameters file)")
    ap.add_argument(
        "--observer", action="append", help="repeat; default: momentum and hofto if calibrated"
    )
    ap.add_argument("--amplitudes", default="2,3,5,7,10,15,20,30", help="[N·m]")
    ap.add_argument("--width", type=float, default=0.4, help="half-sine width [s]")
    ap.add_argument("--rounds", type=int, default=2, help="pulse trains per file and amplitude")
    ap.add_argument("--found", type=float, default=0.95, help="rate that counts as found")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    args.amps = sorted(float(a) for a in args.amplitudes.split(","))
    setup = load_setup(args.params, args.config)
    th = load_thresholds_for(setup, Path(args.thresholds))
    names = args.observer or [o for o in ("momentum", "hofto") if o in th.observers]
    recs = [load_for_replay(setup, Path(f), None) for f in args.files]
    results = [measure(args, name, setup, th, recs) for name in names]
    if args.json:
        print(json.dumps({"thresholds": args.thresholds, "observers": results}, indent=1))
        return 0
    n = setup.model.n
    for res in results:
        print(f"{res['observer']}: false alarms per joint {res['false_alarms']}")
        for st in STATES:
            print(f"  {st}: detection rate / median delay [s] per joint")
            for a in args.amps:
                key = f"{a:g}"
                rates, delays = res["rate"][st][key], res["median_delay"][st][key]
                cells = " ".join(
                    "   -      "
                    if rates[j] is None
                    else f"{rates[j]:5.2f}/" + ("  -" if delays[j] is None else f"{delays[j]:.2f}")
                    for j in range(n)
                )
                print(f"  {a:5g} N·m {cells}")
            small = " ".join(
                f"{'>' + format(args.amps[-1], 'g') if v is None else str(v).replace('.0', ''):>6}"
                for v in res["smallest_found"][st]
            )
            print(f"  smallest found ({args.found:g} of tries, 0 false alarms): {small}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
