"""Cost of teach and play in the loop (issue 9): the tick in HOLD, REPLAY and MOVE_TO, and the
slow-path work of the control-socket thread (plan, save, load).

    python tools/bench_teach.py [--seconds 10] [--ticks 3000] [--json]

The ER3A config on the simulated bus, sim clock (ticks back to back, so the figures are the
tick's compute time, the emulated drives and plant included, as ``hofto-hw run`` reports it).
A smooth synthetic taught path of ``--seconds`` at 1 kHz (at rest at both ends) is saved,
loaded, planned (ruckig move to its start + quintic time scaling) and played. Figures:
median / p99 of the tick [µs] per mode, and wall time [ms] of save, load, plan of the path
and of a move to a joint target. Machine-dependent: compare only on one machine.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hofto_hw.config.loader import load_config  # noqa: E402
from hofto_hw.control.joint_motion import HOLD  # noqa: E402
from hofto_hw.control.taught_path import TaughtPathRecorder, save_taught_path  # noqa: E402
from hofto_hw.runtime import teach  # noqa: E402
from hofto_hw.runtime.compose import build  # noqa: E402
from hofto_hw.runtime.timing import Histogram  # noqa: E402


def _ticks(system, n: int) -> dict:
    system.loop.compute = Histogram()
    system.loop.run(max_ticks=n)
    h = system.loop.compute
    return {"median_us": h.percentile(50.0), "p99_us": h.percentile(99.0), "ticks": n}


def _ms(f):
    t0 = time.perf_counter()
    out = f()
    return out, round((time.perf_counter() - t0) * 1e3, 1)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="taught path length [s]")
    parser.add_argument("--ticks", type=int, default=3000, help="ticks measured per mode")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()

    cfg = load_config(ROOT / "configs" / "er3a.yaml")
    system = build(cfg, clock="sim", contact=False)
    model, tick = system.model, system.tick
    dt = 1.0 / system.rate_hz
    system.loop.run(max_ticks=300)
    out: dict = {"hold": _ticks(system, args.ticks)}

    rec = TaughtPathRecorder(model.n, round(args.seconds / 1e-3) + 1)
    t = np.arange(0.0, args.seconds, 1e-3)
    s = 0.5 * (1.0 - np.cos(np.pi * t / args.seconds))
    d = np.array([0.4, -0.2, 0.3, 0.5, -0.3, 0.6])
    for tk, sk in zip(t, s, strict=True):
        rec.push(tk, model.home + sk * d)
    limits = teach.motion_limits(cfg, model)
    with tempfile.TemporaryDirectory() as tmp:
        file = Path(tmp) / "taught.csv"
        _, out["save_ms"] = _ms(lambda: save_taught_path(rec.path(model), file))
        _, out["load_ms"] = _ms(lambda: teach.load_taught_path(file, model))
        pb, out["plan_replay_ms"] = _ms(
            lambda: teach.plan_replay(file, tick.motion.q.copy(), model, limits, dt)
        )
    tick.play_request = pb
    tick.mode_request = pb.mode
    system.loop.run(max_ticks=pb.traj.segments[1] + 100)
    out["replay"] = _ticks(system, min(args.ticks, pb.traj.q.shape[0] - pb.traj.segments[1]))
    tick.mode_request = HOLD
    system.loop.run(max_ticks=3000)
    target = tick.motion.q + 0.2
    pm, out["plan_move_ms"] = _ms(
        lambda: teach.plan_move(target, tick.motion.q.copy(), model, limits, dt)
    )
    tick.play_request = pm
    tick.mode_request = pm.mode
    system.loop.run(max_ticks=2)
    out["move_to"] = _ticks(system, min(args.ticks, pm.traj.q.shape[0] - 5))
    out["taught_s"] = args.seconds
    out["replay_s"] = round(pb.traj.duration, 3)
    system.close()
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    print(f"taught path {args.seconds:g} s -> replay {out['replay_s']:.2f} s (with the move)")
    for mode in ("hold", "replay", "move_to"):
        m = out[mode]
        print(f"tick in {mode}: median {m['median_us']:.0f} µs, p99 {m['p99_us']:.0f} µs")
    print(
        f"slow path: save {out['save_ms']} ms, load {out['load_ms']} ms, plan replay "
        f"{out['plan_replay_ms']} ms, plan move {out['plan_move_ms']} ms"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
