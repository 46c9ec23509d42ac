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

from hofto_hw.replay.runner import replay
from hofto_hw.replay.session import load_for_replay, observer_for
from hofto_hw.replay.setup import load_setup, load_thresholds_for, observer_config
from safety.collision import CollisionMonitor


def lag_response(t: np.ndarray, pulse: np.ndarray, gain: np.ndarray) -> np.ndarray:
    """Momentum-observer response r' = K·(p − r) to an external torque p (N,) or (N, n)."""
    r = np.zeros_like(pulse)
    for k in range(1, t.size):
        dt = t[k] - t[k - 1]
        a = 1.0 - np.exp(-gain * dt)
        r[k] = r[k - 1] + a * (pulse[k] - r[k - 1])
    return r


def tripped(excess: np.ndarray, t: np.ndarray, debounce: float) -> tuple[bool, float]:
    """Whether ``excess`` (N,) bool stays true for ``debounce`` [s]; delay from t[0] [s]."""
    start = None
    for k in range(excess.size):
        if excess[k]:
            if start is None:
                start = k
            if t[k] - t[start] >= debounce - 1e-9:
                return True, float(t[k] - t[0])
        else:
            start = None
    return False, float("nan")


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
    n = setup.model.n
    hits = np.zeros((len(amps), n))
    tries = np.zeros((len(amps), n))
    delays: list[list[list[float]]] = [[[] for _ in range(n)] for _ in amps]
    false_alarms = {}
    for f in args.files:
        rec = load_for_replay(setup, Path(f), None)
        obs = observer_for(args.observer, obs_cfg, setup, rec)
        res = replay(rec, obs, CollisionMonitor(mcfg))
        false_alarms[Path(f).name] = int(np.sum(np.diff(res.detected.astype(int)) == 1))
        t, est, thr = rec.t, res.tau_ext, res.threshold
        for ai, amp in enumerate(amps):
            for j in range(n):
                for _ in range(args.pulses):
                    t0 = rng.uniform(t[0] + 1.0, t[-1] - args.width - 1.0)
                    sel = (t >= t0 - 0.5) & (t <= t0 + args.width + 0.2)
                    tt = t[sel]
                    p = np.where(
                        (tt >= t0) & (tt <= t0 + args.width),
                        amp * np.sin(np.pi * np.clip((tt - t0) / args.width, 0, 1)),
                        0.0,
                    )
                    sign = rng.choice([-1.0, 1.0])
                    r = lag_response(tt, sign * p, np.array(gain[j]))
                    e = np.abs(est[sel, j] + r) > thr[sel, j]
                    after = tt >= t0
                    ok, d = tripped(e[after], tt[after], mcfg.debounce_time)
                    tries[ai, j] += 1
                    if ok:
                        hits[ai, j] += 1
                        delays[ai][j].append(d)
    rate = hits / np.maximum(tries, 1)
    med = [[float(np.median(d)) if d else float("nan") for d in row] for row in delays]
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
