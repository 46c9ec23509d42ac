"""Detection of synthetic contact pulses injected into free-motion recordings (issue 11).

For each recording, the observer and the collision monitor run once; a half-sine pulse of
amplitude A [N·m] and width W [s] on joint j at time t0 is then added to the observer's
estimate through the observer's own linear response (momentum observer: first-order lag with
its gain, on the real time stamps), and the monitor's trip rule (above the threshold for the
debounce time) is applied within [t0, t0 + W + 0.2 s]. False alarms: episodes of the monitor
on the same recordings without pulses. Prints a table; ``--json`` for figures.

    python tools/pulse_detection.py PARAMS THRESHOLDS FILE... [--pulses 20] [--json]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from hofto_hw.replay.pulses import inject_pulses
from hofto_hw.replay.runner import replay
from hofto_hw.replay.session import load_for_replay, observer_for
from hofto_hw.replay.setup import load_setup, load_thresholds_for, observer_config
from safety.collision import CollisionMonitor


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("params")
    ap.add_argument("thresholds")
    ap.add_argument("files", nargs="+")
    ap.add_argument("--observer", default="momentum")
    ap.add_argument("--amplitudes", default="5,10,12,20")
    ap.add_argument("--width", type=float, default=0.4)
    ap.add_argument("--pulses", type=int, default=20, help="pulses per joint, size and file")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    setup = load_setup(args.params)
    th = load_thresholds_for(setup, Path(args.thresholds))
    obs_cfg = observer_config(args.observer, setup, th)
    gain = np.asarray(obs_cfg.gain, dtype=float)
    mcfg = th.observers[args.observer].monitor
    amps = [float(a) for a in args.amplitudes.split(",")]
    rng = np.random.default_rng(args.seed)
    stats = None
    false_alarms = {}
    for f in args.files:
        rec = load_for_replay(setup, Path(f), None)
        obs = observer_for(args.observer, obs_cfg, setup, rec)
        res = replay(rec, obs, CollisionMonitor(mcfg))
        false_alarms[Path(f).name] = int(np.sum(np.diff(res.detected.astype(int)) == 1))
        stats = inject_pulses(
            rec.t,
            res.tau_ext,
            res.threshold,
            gain,
            mcfg.debounce_time,
            amps,
            args.pulses,
            rng,
            args.width,
            stats,
        )
    assert stats is not None
    n = setup.model.n
    rate = stats.rate
    med = stats.median_delay().tolist()
    if args.json:
        print(
            json.dumps(
                {
                    "amplitudes": amps,
                    "rate": rate.tolist(),
                    "median_delay": med,
                    "false_alarms": false_alarms,
                }
            )
        )
        return 0
    print(f"false alarms (episodes without pulses): {false_alarms}")
    print("detection rate per joint, half-sine", args.width, "s; median delay [s]")
    for ai, amp in enumerate(amps):
        cells = " ".join(f"{rate[ai, j]:5.2f}/{med[ai][j]:.3f}" for j in range(n))
        print(f"{amp:5.1f} N·m  {cells}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
