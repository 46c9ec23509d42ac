"""Sensorless drag on the simulated arm (issue 9): drag figures and the "virtual hand"
transparency of HOFTO vs the momentum observer, closed loop in simulated time.

    python tools/bench_drag.py [--observers hofto momentum] [--drift 10] [--replay] [--json]

Per observer (the ER3A config, true arm 10 % off the model, sensor noise, SimBus + emulated
CSP drives, see hofto_hw/experiments/drag_sim.py):

- push: a constant 20 N push at the tool along x for 1.2 s: steady tool speed vs F/B_a,
  off-axis speed, time from the push's end to rest (the command's, the arm's joints below
  0.01 rad/s, the tool below 5 % of F/B_a), the highest tool speed;
- drift: ``--drift S`` seconds with the enabling input held and no push (0 = skip);
- virtual hand: the tool pulled by a spring-damper (500 N/m, 40 N·s/m) toward a hand that
  moves 0.3 m along x at 0.15 m/s: mean and peak interaction force while the hand moves
  (lower = more transparent; the admittance alone needs B_a·v = 30 N) and the lag (the mean
  distance between hand and tool along the line / hand speed);
- replay (``--replay``): 10 s of taught drag recorded, replayed time-scaled: max path error;
- cost: median / p99 of one DragController.update [µs] (machine-dependent: compare only
  on one machine).

The ``summary`` block carries issue 9's keys (drag.*, replay.*) for the first observer.
"""

from __future__ import annotations

import argparse
import gc
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hofto_hw.control.path_timing import Limits, replay_trajectory  # noqa: E402
from hofto_hw.control.taught_path import TaughtPathRecorder  # noqa: E402
from hofto_hw.experiments.drag_sim import (  # noqa: E402
    DragSim,
    ToolPush,
    VirtualHand,
    drag_figures,
    drift_mps,
    path_error_mm,
    tool_motion,
)

PRESS = 0.3


def _pressed(t: float) -> bool:
    return t > PRESS


def push_figures(observer: str) -> dict:
    sim = DragSim(observer=observer)
    push = ToolPush((20.0, 0.0, 0.0), 0.8, 2.0)
    sim.world.pushes.append(push)
    run = sim.run(2.6, pressed=_pressed)
    return drag_figures(run, push, sim.drag_cfg.damping, sim.drag_cfg.standstill_speed)


def drift_figures(observer: str, seconds: float) -> dict:
    sim = DragSim(observer=observer)
    run = sim.run(PRESS + 0.1 + seconds, pressed=_pressed)
    return drift_mps(run, start=PRESS + 0.1)


def virtual_hand(observer: str) -> dict:
    sim = DragSim(observer=observer)
    hand = VirtualHand(start=0.8)
    sim.world.hand = hand
    run = sim.run(hand.start + hand.length / hand.speed + 1.0, pressed=_pressed)
    moving = (run.t > hand.start + 0.5) & (run.t < hand.start + hand.length / hand.speed)
    f = np.linalg.norm(run.hand_force[moving], axis=1)
    u = np.asarray(hand.direction, dtype=float)
    hand_pos = np.array([hand.hand(t)[0] for t in run.t[moving]])
    gap = (hand_pos - run.tool[moving]) @ u
    return {
        "mean_force_n": float(f.mean()),
        "peak_force_n": float(f.max()),
        "lag_ms": float(1e3 * gap.mean() / hand.speed),
        "admittance_force_n": sim.drag_cfg.damping * hand.speed,
        "stopped": run.stop_tick >= 0,
    }


def replay_figures(observer: str) -> dict:
    sim = DragSim(observer=observer)
    sim.world.pushes += [
        ToolPush((20.0, 0.0, 0.0), 0.5, 3.5, 0.1),
        ToolPush((0.0, 20.0, 0.0), 3.5, 6.5, 0.1),
        ToolPush((-15.0, -10.0, 15.0), 6.5, 9.5, 0.1),
    ]
    rec = TaughtPathRecorder(sim.model.n, 12000)
    sim.run(PRESS + 10.2, pressed=lambda t: PRESS < t < PRESS + 10.0, recorder=rec)
    path = rec.path(sim.model)
    sim.clear_stop()
    vel, acc, jerk = sim.cfg.motion.limits(sim.model)
    lim = Limits(np.array(vel), np.array(acc), np.array(jerk))
    traj = replay_trajectory(sim.group.q, path.t, path.q, lim, sim.dt)
    replay = sim.run(traj.duration + 0.3, trajectory=(traj.q, traj.qd, traj.qdd))
    taught, _ = tool_motion(sim.plant.true_model, path.q, np.zeros_like(path.q))
    jerk_ratio = np.abs(np.diff(traj.qdd, axis=0)).max(axis=0) / sim.dt / lim.jerk
    return {
        "max_path_error_mm": path_error_mm(taught, replay.tool[traj.segments[1] :]),
        "taught_s": float(path.t[-1]),
        "replay_path_s": float((traj.q.shape[0] - traj.segments[1]) * sim.dt),
        "time_scale": traj.scale,
        "max_jerk_ratio": float(jerk_ratio.max()),
    }


def cost(observer: str, ticks: int = 3000) -> dict:
    sim = DragSim(observer=observer, drag={"force_deadband": 0.0})
    drag, g = sim.drag, sim.group
    q, qd = g.q.copy(), np.zeros(sim.model.n)
    tau = np.full(sim.model.n, 0.5)
    drag.update(q, qd, tau, sim.dt, False, False)
    drag.update(q, qd, tau, sim.dt, True, False)
    out = np.empty(ticks)
    clock = time.perf_counter_ns
    gc.disable()
    try:
        for k in range(ticks):
            t0 = clock()
            drag.update(q, qd, tau, sim.dt, True, False)
            out[k] = (clock() - t0) / 1e3
    finally:
        gc.enable()
    return {"median_us": float(np.median(out)), "p99_us": float(np.percentile(out, 99))}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--observers", nargs="+", default=["hofto", "momentum"])
    parser.add_argument("--drift", type=float, default=10.0, help="seconds; 0 = skip")
    parser.add_argument("--replay", action="store_true", help="also teach and replay 10 s")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    results: dict[str, dict] = {}
    for name in args.observers:
        r: dict[str, dict] = {"push": push_figures(name), "virtual_hand": virtual_hand(name)}
        if args.drift > 0:
            r["drift"] = drift_figures(name, args.drift)
        if args.replay:
            r["replay"] = replay_figures(name)
        r["cost"] = cost(name)
        results[name] = r
    first = results[args.observers[0]]
    summary = {
        "drag.observer": args.observers[0],
        "drag.steady_speed_mps": first["push"]["steady_speed_mps"],
        "drag.expected_speed_mps": first["push"]["expected_speed_mps"],
        "drag.rest_time_ms": first["push"]["rest_time_ms"],
        "drag.max_speed_mps": first["push"]["max_speed_mps"],
    }
    if "drift" in first:
        summary["drag.drift_mps"] = first["drift"]["drift_mps"]
    if "replay" in first:
        summary["replay.max_path_error_mm"] = first["replay"]["max_path_error_mm"]
    if args.json:
        print(json.dumps({"summary": summary, "results": results}, indent=2))
        return 0
    for name, r in results.items():
        p, h = r["push"], r["virtual_hand"]
        print(f"{name}:")
        print(
            f"  push 20 N: steady {p['steady_speed_mps'] * 1e3:.1f} mm/s "
            f"(F/B_a {p['expected_speed_mps'] * 1e3:.1f}), off-axis "
            f"{p['off_axis_mps'] * 1e3:.2f} mm/s, max {p['max_speed_mps'] * 1e3:.1f} mm/s"
        )
        print(
            f"  rest after release: command {p['rest_time_command_ms']:.0f} ms, joints "
            f"{p['rest_time_ms']:.0f} ms, tool<5% {p['rest_time_tool_ms']:.0f} ms"
        )
        print(
            f"  virtual hand: mean {h['mean_force_n']:.1f} N (admittance alone "
            f"{h['admittance_force_n']:.0f} N), peak {h['peak_force_n']:.1f} N, "
            f"lag {h['lag_ms']:.0f} ms"
        )
        if "drift" in r:
            d = r["drift"]
            print(
                f"  drift, no push: {d['drift_mps'] * 1e3:.3f} mm/s net, "
                f"{d['drift_peak_mps'] * 1e3:.3f} mm/s peak 1 s mean"
            )
        if "replay" in r:
            rp = r["replay"]
            print(
                f"  replay: max path error {rp['max_path_error_mm']:.2f} mm, time scale "
                f"{rp['time_scale']:.2f}, max jerk {rp['max_jerk_ratio']:.2f} of the limit"
            )
        c = r["cost"]
        print(f"  DragController.update: median {c['median_us']:.0f} µs, p99 {c['p99_us']:.0f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
