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
read-only), and the time [ms] from sending a stop on a new connection to its answer
(median, p99, max), ``--stops`` times through the stop socket (``<socket>.stop``,
hofto_hw/control_plane/stop_server.py: answered once the loop acknowledged it) and as many
times through the control socket's ``stop``, alternately (each stop is reset before the
next). For every stop slower than 50 ms: how many ticks the loop made meanwhile (from the
flight recorder's ring: a loop that made far fewer ticks than milliseconds passed was
itself not running, i.e. the machine did not schedule it), its longest wake-up lateness in
those ticks, and the tick the stop latched at; the stop socket's own time (line read to the
loop's acknowledgement) too. The machine's load average is recorded per phase. The replay
is measured twice: stops timed while a taught path is planned (that plan is then refused:
a stop moved the hold it started from), then a second plan of the same path played for
``--seconds`` and one stop (stop socket) ending it. First, the cost of the loop's poll of
the channel (``LoopPort.poll``, between ticks) on a sim-clock loop. Figures only: the tests
assert behaviour.
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
from hofto_hw.control_plane.protocol import stop_path  # noqa: E402
from hofto_hw.model.robot import RobotModel  # noqa: E402
from safety.stop import Fault  # noqa: E402

CONFIG = ROOT / "configs" / "er3a.yaml"
PHASES = ("quiet", "flood", "line_10mb", "trickle", "idle", "replay", "quiet_end")
STOP_BIT = 1 << int(Fault.STOP_REQUEST)


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


# abusers of the control socket (each run as a process of its own until ``done`` is set);
# tests/hofto_hw/control_plane/test_stop_socket.py runs the same ones
def flood(sock: Path, done: threading.Event) -> None:
    """Status requests, 100 per write, never reading a reply."""
    line = pr.dumps({"cmd": "status"}) * 100
    while not done.is_set():
        try:
            with _raw(sock) as s:
                while not done.is_set():
                    s.sendall(line)
        except OSError:
            pass


def big_line(sock: Path, done: threading.Event) -> None:
    """10 MB without a newline, again and again."""
    blob = b"a" * (10 << 20)
    while not done.is_set():
        try:
            with _raw(sock) as s:
                s.sendall(blob)
        except OSError:
            pass


def trickle(sock: Path, done: threading.Event) -> None:
    """One byte of a line every 0.2 s."""
    while not done.is_set():
        try:
            with _raw(sock) as s:
                while not done.is_set():
                    s.sendall(b"{")
                    time.sleep(0.2)
        except OSError:
            pass


def idle(sock: Path, done: threading.Event) -> None:
    """20 connections (more than the control socket allows) that send nothing."""
    conns = []
    try:
        for _ in range(20):
            conns.append(_raw(sock))
        done.wait()
    except OSError:
        done.wait()
    finally:
        for c in conns:
            c.close()


SLOW_MS = 50.0  # a stop slower than this is looked at (the bound)


def _stop_latency(robot: Robot, sock: Path, reader: RingReader, via: str) -> dict:
    """One timed stop through ``via`` ("stop": the stop socket, "control": the control
    socket), then its reset; the loop's tick (newest record) when it was sent and answered."""
    tick0 = reader.latest_tick()
    mono = time.monotonic_ns
    t0 = mono()
    with Connection(stop_path(sock) if via == "stop" else sock) as c:
        tc = mono()  # connected: the line goes out now
        r = c.call({"cmd": "stop"})
        t1 = mono()
    dt = (t1 - t0) * 1e-6
    tick1 = reader.latest_tick()
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
    out = {"via": via, "ms": dt, "tick0": tick0, "tick1": tick1}
    if "server_ms" in r:
        out["server_ms"] = float(r["server_ms"])
        out["ack_tick"] = int(r["tick"])
        if "read_ns" in r:  # where the time went (one clock, CLOCK_MONOTONIC)
            out["parts_ms"] = {
                "connect": round((tc - t0) * 1e-6, 2),
                "to_server": round((int(r["read_ns"]) - tc) * 1e-6, 2),
                "server": round((int(r["ack_ns"]) - int(r["read_ns"])) * 1e-6, 2),
                "back_to_client": round((t1 - int(r["ack_ns"])) * 1e-6, 2),
            }
    return out


def _stats(values: list[float]) -> dict:
    if not values:
        return {"median": None, "p99": None, "max": None, "n": 0}
    v = np.array(values)
    return {
        "median": round(float(np.median(v)), 2),
        "p99": round(float(np.percentile(v, 99)), 2),
        "max": round(float(v.max()), 2),
        "n": len(values),
    }


class Ticks:
    """What the flight recorder's ring says per tick: wake-up lateness [µs], stop latched."""

    def __init__(self) -> None:
        self.tick: list[int] = []
        self.wake: list[float] = []
        self.stop: list[bool] = []

    def take(self, reader: RingReader) -> None:
        for r, _ in reader.read():
            self.tick.append(int(r["tick"]))
            self.wake.append(float(r["wakeup_us"]))
            self.stop.append(bool(int(r["faults"]) & STOP_BIT))

    def wakeup(self) -> dict:
        w = np.array(self.wake) if self.wake else np.zeros(1)
        return {
            "median": round(float(np.median(w)), 1),
            "p99": round(float(np.percentile(w, 99)), 1),
            "max": round(float(w.max()), 1),
        }

    def explain(self, s: dict) -> dict:
        """A slow stop: the loop's ticks meanwhile, its longest lateness then, the latch."""
        t = np.array(self.tick, dtype=np.int64)
        sel = (t >= s["tick0"]) & (t <= s["tick1"] + 1)
        late = max((w for w, k in zip(self.wake, sel, strict=True) if k), default=0.0)
        latched = next(
            (k for k, st in zip(self.tick, self.stop, strict=True) if k > s["tick0"] and st),
            None,
        )
        made = s["tick1"] - s["tick0"]
        out = {
            "via": s["via"],
            "ms": round(s["ms"], 2),
            "loop_ticks_meanwhile": made,
            "loop_max_late_ms": round(late / 1e3, 2),
            "latched_after_ticks": None if latched is None else latched - s["tick0"],
            # the loop made fewer than half the ticks the time allowed: it was not running
            "loop_stalled": made < 0.5 * s["ms"],
        }
        if "server_ms" in s:
            out["server_ms"] = s["server_ms"]
        if "parts_ms" in s:
            out["parts_ms"] = s["parts_ms"]
        return out


def _stops_summary(stops: list[dict], ticks: Ticks) -> dict:
    return {
        "stop_socket_ms": _stats([s["ms"] for s in stops if s["via"] == "stop"]),
        "control_socket_ms": _stats([s["ms"] for s in stops if s["via"] == "control"]),
        # the stop server's part (line read to the loop's acknowledgement); the rest of a
        # stop socket's time is the client's connect, send and wake-up (this process's)
        "stop_server_ms": _stats([s["server_ms"] for s in stops if "server_ms" in s]),
        # where a stop socket's time goes, each part's median and max [ms]
        "stop_parts_ms": {
            k: _stats([s["parts_ms"][k] for s in stops if "parts_ms" in s])
            for k in ("connect", "to_server", "server", "back_to_client")
        },
        "slow_stops": [ticks.explain(s) for s in stops if s["ms"] > SLOW_MS],
    }


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
    load0 = os.getloadavg()[0]
    ctx = mp.get_context("fork")
    done = ctx.Event()
    procs = []
    if work is not None:
        for f in work if isinstance(work, list) else [work]:
            pr_ = ctx.Process(target=f, args=(sock, done), daemon=True)
            pr_.start()
            procs.append(pr_)
    ticks = Ticks()
    stops: list[dict] = []
    n_stops = 2 * args.stops  # alternately through the stop socket and the control socket
    end = time.monotonic() + args.seconds
    next_stop = time.monotonic() + args.seconds / (n_stops + 1)
    while time.monotonic() < end:
        ticks.take(reader)
        if time.monotonic() >= next_stop and len(stops) < n_stops:
            stops.append(_stop_latency(robot, sock, reader, ("stop", "control")[len(stops) % 2]))
            next_stop += args.seconds / (n_stops + 1)
        time.sleep(0.05)
    ticks.take(reader)
    done.set()
    for pr_ in procs:
        pr_.join(timeout=30.0)
        if pr_.is_alive():
            pr_.kill()
    after = robot.status()["overruns"]
    return {
        "phase": name,
        "ticks": len(ticks.wake),
        "overruns": int(after - before),
        "wakeup_us": ticks.wakeup(),
        **_stops_summary(stops, ticks),
        "load": [round(load0, 2), round(os.getloadavg()[0], 2)],
        "skipped_by_reader": reader.skipped,
    }


def _clear(robot: Robot) -> None:
    for _ in range(100):  # a log_failure of an earlier phase (a loaded machine) is reset
        if not robot.state().faults:
            break
        try:
            robot.reset()
        except Refused:
            time.sleep(0.1)


def _replay_phases(robot: Robot, sock: Path, reader: RingReader, tmp: Path, args) -> list:
    """``replay_planning``: a ``--replay-seconds`` taught path planned while stops are timed
    (the plan is then refused: a stop moved the hold it started from); ``replay_playing``:
    the same path planned again (no stops) and played for ``--seconds``, one stop (stop
    socket) ending it. Missed deadlines while planning (the planner's CPU beside the loop)
    and while playing (the loop following the plan, the control plane streaming it)."""
    out = []
    for name in ("replay_planning", "replay_playing"):
        _clear(robot)
        file = _long_path(tmp, args.replay_seconds, robot.state().q_cmd)
        for _ in reader.read():  # skip to now
            pass
        load0 = os.getloadavg()[0]
        ticks = Ticks()
        stops: list[dict] = []
        got: dict = {}

        def plan(file: Path = file, got: dict = got) -> None:
            with Robot.connect(socket=sock) as r2:
                for attempt in range(20):  # a fault latched meanwhile (log_failure on a
                    try:  # loaded machine): reset, ask again (in the figures: "attempts")
                        got["message"] = r2.replay(file, wait=False).message
                        got["attempts"] = attempt + 1
                        return
                    except Refused as exc:
                        got["refused"] = str(exc)
                        if "latched" not in str(exc):
                            return
                        try:
                            r2.reset()
                        except Refused:
                            time.sleep(0.1)

        o0, t0 = robot.status()["overruns"], time.monotonic()
        t = threading.Thread(target=plan, daemon=True)
        t.start()
        first = t0 + 1.0  # the request taken and the planner running (else refused at once)
        while t.is_alive():
            ticks.take(reader)
            timed = name == "replay_planning" and time.monotonic() > first
            if timed and len(stops) < 2 * args.stops:
                via = ("stop", "control")[len(stops) % 2]
                stops.append(_stop_latency(robot, sock, reader, via))
            time.sleep(0.05 if name == "replay_playing" else 0.25)
        o1, t1 = robot.status()["overruns"], time.monotonic()
        res = {"phase": name, "path_s": args.replay_seconds, "planning_s": round(t1 - t0, 2)}
        if name == "replay_playing":
            if "message" not in got:  # refused (a fault latched on a loaded machine)
                out.append({**res, "error": f"the replay was refused: {got.get('refused')}"})
                continue
            end = t1 + args.seconds
            while time.monotonic() < end:
                ticks.take(reader)
                time.sleep(0.05)
            stops.append(_stop_latency(robot, sock, reader, "stop"))
        ticks.take(reader)
        o2 = robot.status()["overruns"]
        out.append(
            {
                **res,
                "ticks": len(ticks.wake),
                "overruns": int(o2 - o0),
                "overruns_planning": int(o1 - o0),
                "overruns_playing": int(o2 - o1),
                "wakeup_us": ticks.wakeup(),
                **_stops_summary(stops, ticks),
                "load": [round(load0, 2), round(os.getloadavg()[0], 2)],
                "skipped_by_reader": reader.skipped,
                "attempts": got.get("attempts", 1),
            }
        )
        if name == "replay_planning" and "message" in got:
            # a short path planned before the first stop: it plays; stopped (reset by the
            # next phase's _clear), else the next replay is refused ('mode hold first')
            robot.stop()
    return out


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


def _cell(s: dict) -> str:
    if not s["n"]:
        return "-"
    return f"{s['median']}/{s['p99']}/{s['max']} (n={s['n']})"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=10.0, help="per phase")
    ap.add_argument("--stops", type=int, default=20, help="stops timed per phase and per socket")
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
                ("flood", flood),
                ("line_10mb", big_line),
                ("trickle", [trickle] * 8),
                ("idle", idle),
            ):
                if name in phases:
                    out.append(_phase(robot, sock, reader, name, args, work))
            if "replay" in phases:
                out.extend(_replay_phases(robot, sock, reader, tmp, args))
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
        print(f"{'phase':16s} {'ticks':>6s} {'missed':>6s} {'wake p99/max µs':>16s}  "
              f"{'stop socket med/p99/max ms':>27s}  "
              f"{'control socket med/p99/max ms':>30s}  load")  # fmt: skip
        for p in out:
            if "error" in p:
                print(f"{p['phase']:16s} {p['error']}")
                continue
            w, a, b = p["wakeup_us"], p["stop_socket_ms"], p["control_socket_ms"]
            print(
                f"{p['phase']:16s} {p['ticks']:6d} {p['overruns']:6d} "
                f"{w['p99']:7.0f}/{w['max']:<8.0f}  "
                f"{_cell(a):>27s}  {_cell(b):>30s}  {p['load'][0]:.1f}-{p['load'][1]:.1f}"
            )
            if "planning_s" in p:
                print(
                    f"{'':16s} first chunk after {p['planning_s']} s: "
                    f"{p['overruns_planning']} missed while planning, "
                    f"{p['overruns_playing']} while playing"
                )
            for s in p["slow_stops"]:
                who = "the loop was not running (machine)" if s["loop_stalled"] else "the loop ran"
                srv = f", stop server {s['server_ms']} ms" if "server_ms" in s else ""
                if "parts_ms" in s:
                    srv += " (" + ", ".join(f"{k} {v}" for k, v in s["parts_ms"].items()) + ")"
                print(
                    f"{'':16s} slow stop via {s['via']}: {s['ms']} ms, loop made "
                    f"{s['loop_ticks_meanwhile']} ticks, max lateness {s['loop_max_late_ms']} ms"
                    f"{srv}: {who}"
                )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
