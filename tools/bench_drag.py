"""Sensorless drag on the simulated arm (issue 9): drag figures and the "virtual hand"
transparency of HOFTO vs the momentum observer, closed loop in simulated time.

    python tools/bench_drag.py [--observers hofto momentum] [--drift 10] [--replay]
                               [--gains loop|paper] [--hofto-lipschitz L] [--config F] [--json]

Per observer (the ER3A config, true arm 10 % off the model, sensor noise, SimBus + emulated
CSP drives, see hofto_hw/experiments/drag_sim.py; ``--gains loop``: the observer gains the
service's loop runs, ``paper``: the paper's; ``--hofto-lipschitz``: the loop HOFTO's
Lipschitz constant L replaced in a scratch copy of the config):

- push: a constant 20 N push at the tool along x for 1.2 s: steady tool speed vs F/B_a,
  off-axis speed, time from the push's end (the hand's force is zero) to rest: the tool
  slower than 5 % of the steady speed and every joint below 0.01 rad/s (each criterion
  and the command's also printed), the highest tool speed;
- main-job push: the same push in the README main job's conditions (its post-collision
  pose, 3 kg payload, 3 s of contact-free motion first, so the drag has learned the
  friction model's error): steady speed, off-axis speed, rest time;
- hard push: 80 N along y released at once: the highest tool speed (the limit is
  0.25 m/s) and whether the drag stopped (an off-tool contact names a link);
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
    MAIN_JOB_PATH,
    MAIN_JOB_POSE,
    DragSim,
    ToolPush,
    VirtualHand,
    drag_figures,
    drift_mps,
    path_error_mm,
    tool_motion,
)

PRESS = 0.3


SIM: dict = {}  # DragSim keyword arguments from the command line (config, gains)


def _pressed(t: float) -> bool:
    return t > PRESS


def _sim(observer: str, **kw) -> DragSim:
    return DragSim(observer=observer, **SIM, **kw)


def _scratch_config(config: Path, lipschitz: float, folder: Path) -> Path:
    """A copy of ``config`` in ``folder`` whose loop HOFTO's last gain row (its Lipschitz
    constant) is ``lipschitz``; relative paths keep working through links."""

    from hofto_hw.config import read_yaml
    from hofto_hw.config.loader import dump_yaml

    data = read_yaml(config, "config file")
    hofto = (data.get("loop") or {}).get("observers", {}).get("hofto")
    if hofto is None:
        raise SystemExit(f"{config}: loop.observers.hofto: missing (--hofto-lipschitz)")
    hofto["gains"][-1] = [float(lipschitz)] * len(hofto["gains"][-1])
    for item in config.parent.iterdir():
        if item != config:
            (folder / item.name).symlink_to(item.resolve())
    out = folder / config.name
    out.write_text(dump_yaml(data, sort_keys=False))
    return out


def push_figures(observer: str) -> dict:
    sim = _sim(observer)
    push = ToolPush((20.0, 0.0, 0.0), 0.8, 2.0)
    sim.world.pushes.append(push)
    run = sim.run(2.6, pressed=_pressed)
    return drag_figures(run, push, sim.drag_cfg.damping, sim.drag_cfg.standstill_speed)


def main_job_push(observer: str) -> dict:
    """The 20 N push in the README main job's conditions: its post-collision pose, the 3 kg
    payload, contact-free motion before (the drag learns the friction model's error)."""
    sim = _sim(observer, payload=True, q0=MAIN_JOB_POSE)
    sim.free_motion(*MAIN_JOB_PATH, duration=3.0)
    t0 = sim.t
    push = ToolPush((20.0, 0.0, 0.0), t0 + 0.8, t0 + 2.0)
    sim.world.pushes.append(push)
    run = sim.run(2.6, pressed=lambda t: t > t0 + 0.3)
    return drag_figures(run, push, sim.drag_cfg.damping, sim.drag_cfg.standstill_speed)


def hard_push(observer: str) -> dict:
    sim = _sim(observer)
    push = ToolPush((0.0, 80.0, 0.0), 0.8, 2.0)
    sim.world.pushes.append(push)
    run = sim.run(2.6, pressed=_pressed)
    speed = np.linalg.norm(run.tool_v, axis=1)
    return {
        "max_speed_mps": float(speed.max()),
        "limit_mps": sim.drag_cfg.max_tool_speed,
        "stopped": bool(run.stop_tick >= 0),
        "stop_reason": int(run.reason[run.stop_tick]) if run.stop_tick >= 0 else 0,
        "contact_link": int(run.contact_link),
    }


def drift_figures(observer: str, seconds: float) -> dict:
    sim = _sim(observer)
    run = sim.run(PRESS + 0.1 + seconds, pressed=_pressed)
    return drift_mps(run, start=PRESS + 0.1)


def virtual_hand(observer: str) -> dict:
    sim = _sim(observer)
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
    sim = _sim(observer)
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
    sim = _sim(observer, drag={"force_deadband": 0.0})
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
    parser.add_argument("--gains", choices=("loop", "paper"), default="loop")
    parser.add_argument("--config", type=Path, default=None, help="system config (ER3A)")
    parser.add_argument(
        "--hofto-lipschitz", type=float, default=None, help="loop HOFTO's L in a scratch copy"
    )
    args = parser.parse_args()
    import tempfile

    from hofto_hw.experiments.drag_sim import ER3A

    scratch = tempfile.TemporaryDirectory()
    config = args.config or ER3A
    if args.hofto_lipschitz is not None:
        config = _scratch_config(config, args.hofto_lipschitz, Path(scratch.name))
    SIM.update(config=config, gains=args.gains)
    results: dict[str, dict] = {}
    for name in args.observers:
        r: dict[str, dict] = {
            "push": push_figures(name),
            "main_job_push": main_job_push(name),
            "hard_push": hard_push(name),
            "virtual_hand": virtual_hand(name),
        }
        if args.drift > 0:
            r["drift"] = drift_figures(name, args.drift)
        if args.replay:
            r["replay"] = replay_figures(name)
        r["cost"] = cost(name)
        results[name] = r
    first = results[args.observers[0]]
    summary = {
        "drag.observer": args.observers[0],
        "drag.gains": args.gains,
        "drag.hofto_lipschitz": args.hofto_lipschitz,
        "drag.steady_speed_mps": first["push"]["steady_speed_mps"],
        "drag.expected_speed_mps": first["push"]["expected_speed_mps"],
        "drag.off_axis_mps": first["push"]["off_axis_mps"],
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
    lip = f", HOFTO L = {args.hofto_lipschitz:g}" if args.hofto_lipschitz is not None else ""
    print(f"observer gains: {args.gains}{lip}")
    for name, r in results.items():
        p, h = r["push"], r["virtual_hand"]
        print(f"{name}:")
        print(
            f"  push 20 N: steady {p['steady_speed_mps'] * 1e3:.1f} mm/s "
            f"(F/B_a {p['expected_speed_mps'] * 1e3:.1f}), off-axis "
            f"{p['off_axis_mps'] * 1e3:.2f} mm/s, max {p['max_speed_mps'] * 1e3:.1f} mm/s"
        )
        print(
            f"  rest after release: {p['rest_time_ms']:.0f} ms (tool<5% of steady "
            f"{p['rest_time_tool_ms']:.0f} ms, joints<0.01 rad/s {p['rest_time_joints_ms']:.0f} "
            f"ms, command {p['rest_time_command_ms']:.0f} ms)"
        )
        m = r["main_job_push"]
        print(
            f"  main-job push 20 N: steady {m['steady_speed_mps'] * 1e3:.1f} mm/s, off-axis "
            f"{m['off_axis_mps'] * 1e3:.2f} mm/s, rest {m['rest_time_ms']:.0f} ms"
        )
        hp = r["hard_push"]
        stop = f"stopped (reason {hp['stop_reason']}, link {hp['contact_link']})"
        print(
            f"  80 N released: max {hp['max_speed_mps'] * 1e3:.1f} mm/s (limit "
            f"{hp['limit_mps'] * 1e3:.0f}), {stop if hp['stopped'] else 'no stop'}"
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
