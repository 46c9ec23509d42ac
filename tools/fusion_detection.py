"""Fusion of HOFTO and the momentum observer (issue 11): detection of injected contacts and
false alarms on free-motion recordings, momentum alone vs HOFTO alone vs ``mean`` fusion.

A contact P(t) (half-sine, amplitude A [N·m], width W [s], random sign) on joint j is
injected into the MEASURED motor torque as tau - P: an arm whose position loop holds its
motion carries the contact in its motor torque, so every observer sees it through its own
dynamics (HOFTO is nonlinear: no linear response can stand in for it). Pulses are spaced
3 s apart, cycling over the joints, one replay per recording and amplitude. Each variant is
the one monitor (safety/collision/) with the thresholds file's rows: ``momentum`` and
``hofto`` alone, and ``mean`` (the mean of both rows' ratios must exceed 1, each row with its
own thresholds: the file's ``fusion:`` monitors when it has them, calibrated on the fused
ratio by ``hofto-hw tune``). Detection: the monitor trips within [t0, t0 + W + 0.2 s] where it
did not without the pulse. False alarms: trip episodes on the recordings without pulses.

    python tools/fusion_detection.py PARAMS THRESHOLDS FILE... [--amplitudes 5,10,20] [--json]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hofto_hw.replay.runner import run_observer  # noqa: E402
from hofto_hw.replay.session import load_for_replay, observer_for  # noqa: E402
from hofto_hw.replay.setup import load_setup, load_thresholds_for, observer_config  # noqa: E402
from safety.collision import CollisionLevels, from_thresholds  # noqa: E402

ROWS = ("hofto", "momentum")
VARIANTS = {"momentum": (["momentum"], "any"), "hofto": (["hofto"], "any"), "mean": (ROWS, "mean")}


def detections(monitors, variant: str, rec, est: np.ndarray) -> np.ndarray:
    """Detected flag (N,) of one variant over estimates est (N, 2, n)."""
    deciding, logic = VARIANTS[variant]
    mon = CollisionLevels.from_params(
        from_thresholds(monitors, deciding=deciding, logic=logic), backend="auto"
    )
    t, qd = rec.t, rec.qd
    mon.reset(qd[0])
    out = np.zeros(t.size, dtype=bool)
    for k in range(1, t.size):
        out[k] = mon.step(est[k], qd[k], None, float(t[k] - t[k - 1]), k)
    return out


def estimates(setup, th, rec) -> np.ndarray:
    cols = []
    for name in ROWS:
        cfg = observer_config(name, setup, th)
        cols.append(run_observer(rec, observer_for(name, cfg, setup, rec, backend="auto")))
    return np.stack(cols, axis=1)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("params")
    ap.add_argument("thresholds")
    ap.add_argument("files", nargs="+")
    ap.add_argument("--amplitudes", default="5,10,20")
    ap.add_argument("--width", type=float, default=0.4)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    setup = load_setup(args.params)
    th = load_thresholds_for(setup, Path(args.thresholds))
    single = {name: th.observers[name].monitor for name in ROWS}
    # ``mean`` judged with the thresholds calibrated on the fused ratio when the file has them
    fused = single if th.fusion is None else {name: th.fusion.monitors[name] for name in ROWS}
    per_variant = {v: fused if v == "mean" else single for v in VARIANTS}
    amps = [float(a) for a in args.amplitudes.split(",")]
    n = setup.model.n
    rng = np.random.default_rng(args.seed)
    hits = {v: np.zeros((len(amps), n)) for v in VARIANTS}
    tries = np.zeros((len(amps), n))
    false_alarms = {v: 0 for v in VARIANTS}
    for f in args.files:
        rec = load_for_replay(setup, Path(f), None)
        base = estimates(setup, th, rec)
        quiet = {v: detections(per_variant[v], v, rec, base) for v in VARIANTS}
        for v in VARIANTS:
            false_alarms[v] += int(np.sum(np.diff(quiet[v].astype(int)) == 1))
        t = rec.t
        starts = np.arange(t[0] + 1.5, t[-1] - args.width - 1.0, 3.0)
        for ai, amp in enumerate(amps):
            tau = rec.tau.copy()
            windows = []
            for i, t0 in enumerate(starts):
                j = (i + ai) % n
                phase = np.clip((t - t0) / args.width, 0.0, 1.0)
                tau[:, j] -= rng.choice([-1.0, 1.0]) * amp * np.sin(np.pi * phase)
                windows.append((j, (t >= t0) & (t <= t0 + args.width + 0.2)))
            est = estimates(setup, th, dataclasses.replace(rec, tau=tau))
            for v in VARIANTS:
                det = detections(per_variant[v], v, rec, est)
                for j, sel in windows:
                    hits[v][ai, j] += bool(np.any(det[sel] & ~quiet[v][sel]))
            for j, _ in windows:
                tries[ai, j] += 1
    rates = {v: (hits[v] / np.maximum(tries, 1)).tolist() for v in VARIANTS}
    res = {"amplitudes": amps, "tries": tries.tolist(), "rate": rates, "false_alarms": false_alarms}
    if args.json:
        print(json.dumps(res))
        return 0
    print(f"pulses per cell: {tries.min():.0f}-{tries.max():.0f}; false alarms {false_alarms}")
    for ai, amp in enumerate(amps):
        for v in VARIANTS:
            row = " ".join(f"{x:4.2f}" for x in rates[v][ai])
            print(f"{amp:5.1f} N·m {v:9s} {row}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
