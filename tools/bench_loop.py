"""Loop timing on the simulated bus in real time: overruns, wake-up latency and tick compute
(median / p99 / p99.9 / max), CPU % of the loop, at several rates, with and without
SCHED_FIFO, with logging off (in-memory sink) and on (the MCAP FlightRecorder as the sink:
its writer process's CPU % and the records dropped/lost are reported too). Prints figures;
``--json`` prints them as JSON; ``--quick`` runs 3 s per case.

Per case also: the machine's 1-minute load average before and after, the stalls (wake-ups
later than 5 ms and than 50 ms: on a shared VM the host steals the CPU for 10-110 ms a few
times a minute) and the overrun-fault episodes (times the missed-deadline streak reached
``safety.overrun_streak``; the first one latches the fault and stops the arm, as configured,
the run goes on so that later episodes are counted too).

    python tools/bench_loop.py --quick
    python tools/bench_loop.py --seconds 60 --rates 1000 --fifo on --log both --json
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _proc_cpu_s(pid: int) -> float:
    """User + system CPU seconds of process ``pid`` so far (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _recorder(cfg, folder: str):
    from hofto_hw.recording.flight_file import LogSpec
    from hofto_hw.recording.recorder import FlightRecorder
    from hofto_hw.runtime.compose import loop_observer_names

    names = loop_observer_names(cfg)
    spec = LogSpec(Path(folder) / "bench.mcap", list(cfg.robot.joints), names)
    return FlightRecorder(spec).start()


def _count_overrun_episodes(tick, rate: float) -> list[int]:
    """Wrap ``tick._overrun`` to count, in place in the returned list: the times the
    missed-deadline streak reached the limit, and the wake-ups that missed at least 5 ms and
    at least 50 ms of deadlines (a few hundred ns per tick)."""
    count = [0, 0, 0]
    inner = tick._overrun
    five, fifty = max(1, round(0.005 * rate)), max(1, round(0.05 * rate))

    def counted(missed: int) -> None:
        before = tick.overrun_streak
        inner(missed)
        if tick.overrun_streak >= tick.overrun_limit > before:
            count[0] += 1
        if missed >= five:
            count[1] += 1
            if missed >= fifty:
                count[2] += 1

    tick._overrun = counted
    return count


def _case(conn, config: str, rate: float, seconds: float, fifo: bool, log: bool) -> None:
    from hofto_hw.config import load_config
    from hofto_hw.control.joint_motion import MOVE
    from hofto_hw.runtime import realtime
    from hofto_hw.runtime.compose import build

    cfg = load_config(config)
    bus = cfg.bus.model_copy(update={"cycle_time": 1.0 / rate})
    loop_cfg = cfg.loop.model_copy(update={"rate_hz": rate})
    cfg = cfg.model_copy(update={"bus": bus, "loop": loop_cfg})
    rt = realtime.setup(
        "preferred" if fifo else "off", cfg.loop.priority, cfg.loop.cpus, cfg.loop.cpu_latency_us
    )
    tmp = tempfile.TemporaryDirectory(prefix="bench-loop-")
    rec = _recorder(cfg, tmp.name) if log else None
    system = build(cfg, clock="real", sink=rec, contact=False)
    tick = system.tick
    tick.mode_request = MOVE
    episodes = _count_overrun_episodes(tick, rate)
    load0 = os.getloadavg()[0]
    w0 = _proc_cpu_s(rec.writer_pid) if rec is not None else 0.0
    r0 = resource.getrusage(resource.RUSAGE_SELF)
    t0 = time.monotonic()
    end = t0 + seconds
    # ``seconds`` of wall time: on a starved machine (no SCHED_FIFO) most deadlines are
    # missed, and a tick count would stretch the case to many times its length
    system.loop.run(should_stop=lambda: time.monotonic() >= end)
    wall = time.monotonic() - t0
    r1 = resource.getrusage(resource.RUSAGE_SELF)
    w1 = _proc_cpu_s(rec.writer_pid) if rec is not None else 0.0
    realtime.drop_realtime()
    load1 = os.getloadavg()[0]
    cpu = (r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime) / wall * 100.0
    system.close()
    health = rec.close() if rec is not None else None
    tmp.cleanup()
    conn.send(
        {
            "rate_hz": rate,
            "sched_fifo": rt.fifo,
            "seconds": round(wall, 2),
            "ticks": system.loop.ticks,
            "overruns": system.tick.overruns,
            "overrun_pct": round(100.0 * system.tick.overruns / max(1, system.loop.ticks), 3),
            "faults": system.tick.stop.latched_names(),
            "overrun_fault_episodes": episodes[0],
            "stalls_over_5ms": episodes[1],
            "stalls_over_50ms": episodes[2],
            "load_avg_1min": [round(load0, 2), round(load1, 2)],
            "wakeup_us": system.loop.wakeup.summary(),
            "compute_us": system.loop.compute.summary(),
            "cpu_pct": round(cpu, 1),
            "log": log,
            "writer_cpu_pct": round((w1 - w0) / wall * 100.0, 1) if log else None,
            "log_dropped": None if health is None else health.dropped + health.records_lost,
        }
    )


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--config", default=str(ROOT / "configs" / "er3a.yaml"))
    p.add_argument("--seconds", type=float, default=60.0)
    p.add_argument("--rates", type=float, nargs="+", default=[500.0, 1000.0, 2000.0])
    p.add_argument("--fifo", choices=("on", "off", "both"), default="both", help="SCHED_FIFO")
    p.add_argument("--log", choices=("on", "off", "both"), default="both", help="MCAP recorder")
    p.add_argument("--quick", action="store_true", help="3 s per case")
    p.add_argument("--json", action="store_true")
    p.add_argument("--partial", type=Path, help="append each finished case here (JSON lines)")
    args = p.parse_args()
    seconds = 3.0 if args.quick else args.seconds
    results = []
    choice = {"on": (True,), "off": (False,), "both": (True, False)}
    cases = [
        (rate, fifo, log)
        for rate in args.rates
        for fifo in choice[args.fifo]
        for log in choice[args.log][::-1]
    ]
    for rate, fifo, log in cases:
        a, b = mp.Pipe()
        proc = mp.get_context("spawn").Process(
            target=_case, args=(b, args.config, rate, seconds, fifo, log)
        )
        proc.start()
        results.append(a.recv())
        proc.join()
        if args.partial is not None:  # one JSON line per finished case, kept on a crash
            with args.partial.open("a") as f:
                f.write(json.dumps(results[-1]) + "\n")
    if args.json:
        print(json.dumps(results, indent=2))
        return 0
    for r in results:
        w, c = r["wakeup_us"], r["compute_us"]
        print(
            f"{r['rate_hz']:6.0f} Hz {'FIFO ' if r['sched_fifo'] else 'OTHER'} "
            f"log {'on ' if r['log'] else 'off'} "
            f"{r['ticks']:7d} ticks, overruns {r['overruns']} ({r['overrun_pct']} %), "
            f"CPU loop {r['cpu_pct']} %"
            + (
                f", writer {r['writer_cpu_pct']} %, log records dropped/lost {r['log_dropped']}"
                if r["log"]
                else ""
            )
        )
        print(
            f"    wake-up µs median {w['median']:.0f} p99 {w['p99']:.0f} "
            f"p99.9 {w['p999']:.0f} max {w['max']:.0f}; compute µs median {c['median']:.0f} "
            f"p99 {c['p99']:.0f} p99.9 {c['p999']:.0f} max {c['max']:.0f}"
        )
        print(
            f"    stalls > 5 ms {r['stalls_over_5ms']}, > 50 ms {r['stalls_over_50ms']}; "
            f"overrun-fault episodes {r['overrun_fault_episodes']}; load average "
            f"{r['load_avg_1min'][0]} -> {r['load_avg_1min'][1]}"
        )
        if r["faults"]:
            print(f"    latched: {', '.join(r['faults'])}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
