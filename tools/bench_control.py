"""The loop's timing while clients abuse the control socket, and how fast ``stop`` is answered.

    .venv/bin/python tools/bench_control.py [--seconds 10] [--stops 20] [--replay-seconds 300]
                                            [--phases quiet,flood,...] [--loop-cpus 1] [--json]

Starts ``hofto-hw run --clock real --socket S`` (simulated bus, hold, no scripted collision,
``safety.overrun_streak`` raised to 100000 so that nothing latches and every phase runs) and
measures phase by phase: ``quiet`` (nobody but this script), ``flood`` (a client sending
status requests without reading the replies, reconnecting when closed), ``line_10mb`` (a
client sending 10 MB lines without a newline, again and again), ``trickle`` (eight clients
sending one byte every 0.2 s), ``idle`` (20 idle connections, more than allowed), each
abuser a process of its own (in a thread of this one it would hold up the stop being timed
on this one's GIL), ``replay`` (a ``--replay-seconds`` taught path planned, then played for
``--seconds``: missed deadlines and wake-up p99 while planning (until the loop plays the
first chunk) and while playing apart; no stop is timed while planning, one at the end),
``quiet_end`` (quiet again: on a shared machine the two quiet phases show what the
machine's own noise is); ``--loop-cpus`` pins the loop (and so the control plane and its
planner to the other CPUs). Per phase:
the loop's missed deadlines (the status' ``overruns`` difference), the wake-up latency
median / p99 / max [µs] of every tick of the phase (read from the flight recorder's ring,
read-only), and the time [ms] from sending ``stop`` on a new connection to its answer
(median, max of ``--stops``; each stop is reset before the next). First, the cost of the
loop's poll of the channel (``LoopPort.poll``, between ticks) on a sim-clock loop. Figures
only: the tests assert behaviour.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hofto_hw.client import Refused, Robot  # noqa: E402
from hofto_hw.client.connection import Connection  # noqa: E402
from hofto_hw.client.stream import RingReader  # noqa: E402
from hofto_hw.control.taught_path import TaughtPathRecorder, save_taught_path  # noqa: E402
from hofto_hw.control_plane import protocol as pr  # noqa: E402
from hofto_hw.model.robot import RobotModel  # noqa: E402

CONFIG = ROOT / "configs" / "er3a.yaml"
PHASES = ("quiet", "flood", "line_10mb", "trickle", "idle", "replay", "quiet_end")


def _config(tmp: Path, loop_cpus: list[int] | None = None) -> Path:
    data = yaml.safe_load(CONFIG.read_text())
    if loop_cpus is not None:
        data["loop"]["cpus"] = loop_cpus
    data["robot"]["urdf"] = str((CONFIG.parent / data["robot"]["urdf"]).resolve())
    data["drag"]["enable_input"] = {"source": "socket"}
    data["run"].pop("drag", None)
    data["safety"]["overrun_streak"] = 100000
    out = tmp / "bench.yaml"
    out.write_text(yaml.safe_dump(data))
    return out


def _start(tmp: Path, loop_cpus: list[int] | None = None) -> tuple[subprocess.Popen, Path]:
    sock = tmp / "c.sock"
    cmd = [sys.executable, "-m", "hofto_hw.cli", "run", "--config", str(_config(tmp, loop_cpus))]
    cmd += ["--clock", "real", "--duration", "100000", "--socket", str(sock), "--hold"]
    cmd += ["--no-collision", "--log-dir", str(tmp / "logs")]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(
        cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
    )
    assert proc.stderr is not None
    for line in proc.stderr:
        if line.startswith("hofto-hw run: running"):
            break

    def forward() -> None:  # the service's own lines (a refusal, a fault) to ours
        for line in proc.stderr:  # type: ignore[union-attr]
            sys.stderr.write("service: " + line)

    threading.Thread(target=forward, daemon=True).start()
    return proc, sock


def _raw(path: Path) -> socket.socket:
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    s.connect(str(path))
    return s


def _flood(sock: Path, done: threading.Event) -> None:
    line = pr.dumps({"cmd": "status"}) * 100
    while not done.is_set():
        try:
            with _raw(sock) as s:
                while not done.is_set():
                    s.sendall(line)
        except OSError:
            pass


def _big(sock: Path, done: threading.Event) -> None:
    blob = b"a" * (10 << 20)
    while not done.is_set():
        try:
            with _raw(sock) as s:
                s.sendall(blob)
        except OSError:
            pass


def _trickle(sock: Path, done: threading.Event) -> None:
    while not done.is_set():
        try:
            with _raw(sock) as s:
                while not done.is_set():
                    s.sendall(b"{")
                    time.sleep(0.2)
        except OSError:
            pass


def _idle(sock: Path, done: threading.Event) -> None:
    conns = []
    try:
        for _ in range(20):
            conns.append(_raw(sock))
        done.wait()
    finally:
        for c in conns:
            c.close()


def _stop_latency(robot: Robot, sock: Path) -> float:
    t0 = time.perf_counter()
    with Connection(sock) as c:
        r = c.call({"cmd": "stop"})
    dt = (time.perf_counter() - t0) * 1e3
    assert r["ok"], r
    while "stop_request" not in robot.state().faults:
        time.sleep(0.01)
    for _ in range(100):  # a log_failure (records dropped on a loaded machine) may persist
        try:
            robot.reset()
        except Refused:
            time.sleep(0.1)
            continue
        break
    return dt


def _long_path(tmp: Path, seconds: float, home: np.ndarray) -> Path:
    from hofto_hw.config.loader import load_config

    model = RobotModel.from_config(load_config(CONFIG).robot)
    rec = TaughtPathRecorder(model.n, int(seconds * 1000) + 1)
    t = np.arange(0.0, seconds, 1e-3)
    wave = 0.05 * (1.0 - np.cos(2 * np.pi * t / 20.0))
    for tk, w in zip(t, wave, strict=True):
        rec.push(tk, home + w)
    return save_taught_path(rec.path(model), tmp / "long.csv")


def _phase(robot: Robot, sock: Path, reader: RingReader, name: str, args, work=None) -> dict:
    """``work``: abusers, each in a process of its own (as a real client is: in a thread of
    this one it would share the GIL with the stop being timed)."""
    for _ in reader.read():  # skip to now
        pass
    before = robot.status()["overruns"]
    ctx = mp.get_context("fork")
    done = ctx.Event()
    procs = []
    if work is not None:
        for f in work if isinstance(work, list) else [work]:
            pr_ = ctx.Process(target=f, args=(sock, done), daemon=True)
            pr_.start()
            procs.append(pr_)
    wake: list[float] = []
    stops: list[float] = []
    end = time.monotonic() + args.seconds
    next_stop = time.monotonic() + args.seconds / (args.stops + 1)
    while time.monotonic() < end:
        wake.extend(float(r["wakeup_us"]) for r, _ in reader.read())
        if time.monotonic() >= next_stop and len(stops) < args.stops:
            stops.append(_stop_latency(robot, sock))
            next_stop += args.seconds / (args.stops + 1)
        time.sleep(0.05)
    wake.extend(float(r["wakeup_us"]) for r, _ in reader.read())
    done.set()
    for pr_ in procs:
        pr_.join(timeout=30.0)
        if pr_.is_alive():
            pr_.kill()
    after = robot.status()["overruns"]
    w = np.array(wake) if wake else np.zeros(1)
    return {
        "phase": name,
        "ticks": len(wake),
        "overruns": int(after - before),
        "wakeup_us": {
            "median": round(float(np.median(w)), 1),
            "p99": round(float(np.percentile(w, 99)), 1),
            "max": round(float(w.max()), 1),
        },
        "stop_ms": {
            "median": round(float(np.median(stops)), 2) if stops else None,
            "max": round(float(np.max(stops)), 2) if stops else None,
            "n": len(stops),
        },
        "skipped_by_reader": reader.skipped,
    }


def _replay_phase(robot: Robot, sock: Path, reader: RingReader, tmp: Path, args) -> dict:
    """A ``--replay-seconds`` taught path planned (no stop timed meanwhile: a stop moves the
    hold, and the plan made from it is refused) and then played for ``--seconds``; one
    stop timed at the end (it ends the replay). The missed deadlines while planning (the
    planner's CPU beside the loop) and while playing (the loop following the plan, the
    control plane streaming it) are told apart."""
    for _ in range(100):  # a log_failure of an earlier phase (a loaded machine) is reset
        if not robot.state().faults:
            break
        try:
            robot.reset()
        except Refused:
            time.sleep(0.1)
    file = _long_path(tmp, args.replay_seconds, robot.state().q_cmd)
    for _ in reader.read():  # skip to now
        pass
    wake: list[float] = []
    got: dict = {}

    def plan() -> None:
        with Robot.connect(socket=sock) as r2:
            for attempt in range(20):  # a fault latched meanwhile (log_failure on a loaded
                try:  # machine): reset, ask again (said in the figures: "attempts")
                    got["message"] = r2.replay(file, wait=False).message
                    got["attempts"] = attempt + 1
                    return
                except Refused as exc:
                    if "latched" not in str(exc):
                        raise
                    try:
                        r2.reset()
                    except Refused:
                        time.sleep(0.1)

    o0, t0 = robot.status()["overruns"], time.monotonic()
    t = threading.Thread(target=plan, daemon=True)
    t.start()
    while t.is_alive():
        wake.extend(float(r["wakeup_us"]) for r, _ in reader.read())
        time.sleep(0.05)
    o1, t1 = robot.status()["overruns"], time.monotonic()
    if "message" not in got:  # refused (a fault latched on a loaded machine): said, not fatal
        return {"phase": "replay", "error": "the replay was refused (see the service's output)"}
    n_planning = len(wake)
    end = t1 + args.seconds
    while time.monotonic() < end:
        wake.extend(float(r["wakeup_us"]) for r, _ in reader.read())
        time.sleep(0.05)
    wake.extend(float(r["wakeup_us"]) for r, _ in reader.read())
    o2 = robot.status()["overruns"]
    progress = (robot.status()["playback"] or {}).get("progress", 0.0)
    stop = _stop_latency(robot, sock)
    w = np.array(wake) if wake else np.zeros(1)
    w_plan = w[:n_planning] if n_planning else np.zeros(1)
    w_play = w[n_planning:] if len(w) > n_planning else np.zeros(1)
    return {
        "phase": "replay",
        "ticks": len(wake),
        "overruns": int(o2 - o0),
        "wakeup_us": {
            "median": round(float(np.median(w)), 1),
            "p99": round(float(np.percentile(w, 99)), 1),
            "max": round(float(w.max()), 1),
        },
        "stop_ms": {"median": round(stop, 2), "max": round(stop, 2), "n": 1},
        "skipped_by_reader": reader.skipped,
        "path_s": args.replay_seconds,
        "planning_s": round(t1 - t0, 2),
        "overruns_planning": int(o1 - o0),
        "overruns_playing": int(o2 - o1),
        "wakeup_p99_planning_us": round(float(np.percentile(w_plan, 99)), 1),
        "wakeup_p99_playing_us": round(float(np.percentile(w_play, 99)), 1),
        "progress_at_stop": round(float(progress), 4),
        "attempts": got.get("attempts", 1),
    }


def poll_cost(ticks: int = 5000) -> dict:
    """LoopPort.poll on a sim-clock loop (nothing pending: the common case) [µs]."""
    from hofto_hw.config.loader import load_config
    from hofto_hw.control_plane.channel import Channel
    from hofto_hw.control_plane.port import LoopPort
    from hofto_hw.runtime.compose import build

    system = build(load_config(CONFIG), clock="sim", contact=False)
    chan = Channel(system.tick.n, len(system.tick.observers), create=True)
    port = LoopPort(chan, system).attach()
    system.loop.run(max_ticks=500)
    times = np.zeros(ticks)
    perf = time.perf_counter_ns
    k = [0]

    class Timed:  # the loop calls poll() after every tick: time the real one
        def poll(self) -> None:
            t0 = perf()
            port.poll()
            if k[0] < ticks:
                times[k[0]] = (perf() - t0) * 1e-3
                k[0] += 1

    system.loop.port = Timed()
    system.loop.run(max_ticks=ticks)
    port.detach()
    chan.close()
    system.close()
    return {
        "median_us": round(float(np.median(times)), 2),
        "p99_us": round(float(np.percentile(times, 99)), 2),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=10.0, help="per phase")
    ap.add_argument("--stops", type=int, default=20, help="stops timed per phase")
    ap.add_argument("--replay-seconds", type=float, default=300.0, help="taught path length")
    ap.add_argument(
        "--phases", default=",".join(PHASES), help="comma-separated, of " + ",".join(PHASES)
    )
    ap.add_argument(
        "--loop-cpus",
        default=None,
        help="comma-separated CPUs to pin the loop to (loop.cpus; the control plane and its "
        "planner then run on the others); default: the config's (not pinned)",
    )
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    phases = args.phases.split(",")
    if not set(phases) <= set(PHASES):
        ap.error(f"--phases: {args.phases!r}: each one of {','.join(PHASES)}")
    try:
        loop_cpus = None if args.loop_cpus is None else [int(c) for c in args.loop_cpus.split(",")]
    except ValueError:
        ap.error(f"--loop-cpus: {args.loop_cpus!r}: expected comma-separated CPU numbers")
    poll = poll_cost()
    tmp = Path(tempfile.mkdtemp(prefix="bench-control-"))
    proc, sock = _start(tmp, loop_cpus)
    out = []
    try:
        with Robot.connect(socket=sock) as robot:
            while robot.state().mode != "hold" or np.abs(robot.state().qd).max() > 0.01:
                time.sleep(0.05)
            info = robot._call({"cmd": "stream_info"})
            reader = RingReader(info["shm"], info["caps"][0], robot.n, robot.info["observers"])
            for name, work in (
                ("quiet", None),
                ("flood", _flood),
                ("line_10mb", _big),
                ("trickle", [_trickle] * 8),
                ("idle", _idle),
            ):
                if name in phases:
                    out.append(_phase(robot, sock, reader, name, args, work))
            if "replay" in phases:
                out.append(_replay_phase(robot, sock, reader, tmp, args))
            if "quiet_end" in phases:  # the machine's noise
                out.append(_phase(robot, sock, reader, "quiet_end", args))
            reader.close()
    finally:
        proc.terminate()
        proc.wait(timeout=120)
    if args.json:
        load = os.getloadavg()
        print(
            json.dumps(
                {"poll": poll, "phases": out, "machine": os.uname().nodename,
                 "cpus": os.cpu_count(), "loop_cpus": loop_cpus,
                 "load_after": [round(v, 2) for v in load]},
                indent=2,
            )
        )  # fmt: skip
    else:
        print(f"LoopPort.poll (sim clock, nothing pending): median {poll['median_us']} µs, "
              f"p99 {poll['p99_us']} µs")  # fmt: skip
        for p in out:
            if "error" in p:
                print(f"{p['phase']:12s} {p['error']}")
                continue
            w, s = p["wakeup_us"], p["stop_ms"]
            print(
                f"{p['phase']:12s} {p['ticks']:6d} ticks, {p['overruns']:4d} missed, wake-up "
                f"median {w['median']:.0f} p99 {w['p99']:.0f} max {w['max']:.0f} µs; stop "
                f"answered median {s['median']} ms, max {s['max']} ms (n={s['n']})"
            )
            if "planning_s" in p:
                print(
                    f"{'':12s} first chunk after {p['planning_s']} s: {p['overruns_planning']} "
                    f"missed (wake-up p99 {p['wakeup_p99_planning_us']:.0f} µs) while "
                    f"planning, {p['overruns_playing']} (p99 "
                    f"{p['wakeup_p99_playing_us']:.0f} µs) while playing"
                )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
