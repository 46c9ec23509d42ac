"""Benchmark: the pysoem master and six emulated EtherCAT drives at 1 kHz over a veth pair.

Creates a veth pair, starts ``hofto-hw sim-ethercat`` on one end (its own process), opens
the master on the other, enables the drives in CSP holding position and runs the cyclic
exchange for ``--seconds``. Prints: cycles, WKC errors and lost frames (target 0), the
send -> receive round trip of the process-data frame (median / p99 / p99.9 / max, µs),
cycle overruns, and the CPU use of the master and of the emulator process (% of one core).
Needs root. ``--json`` prints one JSON object instead of the table.

    sudo .venv/bin/python tools/bench_ethercat.py --seconds 60
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _cpu_seconds(pid: int) -> float:
    """utime + stime of a process [s] from /proc."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def start_emulator(iface: str, config: Path, workdir: Path) -> subprocess.Popen:
    """``hofto-hw sim-ethercat`` on ``iface`` for ``config`` (its own process, quiet arm),
    returned once its ready file exists in ``workdir``; SystemExit when it fails to start."""
    from hofto_hw.commands.sim_ethercat import start_emulator as start
    from hofto_hw.errors import UserError

    try:
        return start(iface, config, workdir / "ready", timeout=30.0)
    except UserError as exc:
        raise SystemExit(str(exc)) from None


def _set_fifo(pid: int, priority: int) -> None:
    """SCHED_FIFO for ``pid`` (0 = this process), as a real-time deployment would run."""
    os.sched_setscheduler(pid, os.SCHED_FIFO, os.sched_param(priority))


def run(seconds: float, rate: float, config: Path, fifo: int = 0) -> dict[str, float | int]:
    """Run the benchmark; returns the figures (see module docstring)."""
    from drivers.cia402.drive_group import DriveGroup
    from drivers.cia402.state_machine import Mode
    from drivers.ethercat.master import EtherCATTransport
    from drivers.sim.esc import veth
    from drivers.transport import STATUS_NO_RESPONSE, STATUS_OK, STATUS_WKC_MISMATCH
    from hofto_hw.config.loader import load_config

    cfg = load_config(config)
    assert cfg.bus is not None
    tag = f"{os.getpid() % 100000}"
    master_if, slave_if = f"bm{tag}", f"bs{tag}"
    veth.create_pair(master_if, slave_if)
    proc = None
    t = None
    try:
        with tempfile.TemporaryDirectory() as tmp:
            proc = start_emulator(slave_if, config, Path(tmp))
        if fifo:
            _set_fifo(proc.pid, fifo)
            _set_fifo(0, fifo)
        period = 1.0 / rate
        from drivers.cia402.profiles import profiles_for

        t = EtherCATTransport(
            master_if,
            cfg.bus.drives,
            period,
            list(cfg.robot.joints),
            receive_timeout=0.01,
            profiles=profiles_for(cfg.bus.drives, "ethercat"),  # the config's drive models
        )
        # the group (its kernels compiled and warmed: ~0.5 s on a loaded machine) before the
        # bus opens, as hofto_hw.runtime.compose builds it: after, that gap in the process
        # data outlasts the slaves' 100 ms SM watchdog and takes them out of OP
        g = DriveGroup.from_config(t, cfg.bus)
        t.open()
        g.set_mode(Mode.CSP)
        g.enable()
        q_hold = g.q.copy()

        n_max = int(seconds * rate) + 10
        rtt = np.zeros(n_max)
        m = t.master
        send, receive = m.send_processdata, m.receive_processdata
        clock = time.perf_counter_ns
        stamp = [0]

        def timed_send() -> int:
            stamp[0] = clock()
            return send()

        def timed_receive(timeout: int = 2000) -> int:
            wkc = receive(timeout)
            rtt[k] = (clock() - stamp[0]) / 1000.0
            return wkc

        m.send_processdata = timed_send
        m.receive_processdata = timed_receive
        counts = {STATUS_OK: 0, STATUS_NO_RESPONSE: 0, STATUS_WKC_MISMATCH: 0}
        other = overruns = 0
        cpu_emu0 = _cpu_seconds(proc.pid)
        cpu_me0 = time.process_time()
        wall0 = time.monotonic()
        deadline = wall0
        k = 0
        end = wall0 + seconds
        while k < n_max - 1:
            g.command_position(q_hold)
            status = g.cycle()
            if status in counts:
                counts[status] += 1
            else:
                other += 1
            k += 1
            deadline += period
            now = time.monotonic()
            if now >= end:
                break
            if now > deadline:
                overruns += 1
                deadline = now
            else:
                time.sleep(deadline - now)
        wall = time.monotonic() - wall0
        cpu_me = time.process_time() - cpu_me0
        cpu_emu = _cpu_seconds(proc.pid) - cpu_emu0
        samples = rtt[:k]
        return {
            "seconds": round(wall, 3),
            "rate_hz": rate,
            "sched_fifo_priority": fifo,
            "slaves": len(t.slaves),
            "cycles": k,
            "wkc_errors": counts[STATUS_WKC_MISMATCH],
            "lost_frames": counts[STATUS_NO_RESPONSE],
            "other_errors": other,
            "overruns": overruns,
            "rtt_median_us": round(float(np.median(samples)), 1),
            "rtt_p99_us": round(float(np.percentile(samples, 99)), 1),
            "rtt_p999_us": round(float(np.percentile(samples, 99.9)), 1),
            "rtt_max_us": round(float(samples.max()), 1),
            "cpu_master_pct": round(100.0 * cpu_me / wall, 1),
            "cpu_emulator_pct": round(100.0 * cpu_emu / wall, 1),
        }
    finally:
        if t is not None:
            t.close()
        if proc is not None and proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                proc.kill()
        veth.delete_pair(master_if)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="run time (default 60)")
    parser.add_argument("--rate", type=float, default=1000.0, help="cycle rate [Hz]")
    parser.add_argument("--config", type=Path, default=ROOT / "configs" / "er3a.yaml")
    parser.add_argument(
        "--fifo",
        type=int,
        default=0,
        metavar="PRIO",
        help="run master and emulator with SCHED_FIFO priority PRIO (default 0: normal)",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args()
    if os.geteuid() != 0:
        print("bench_ethercat: needs root (veth pair, raw sockets)", file=sys.stderr)
        return 2
    from hofto_hw.errors import UserError

    try:
        figures = run(args.seconds, args.rate, args.config, args.fifo)
    except UserError as exc:  # a drive or the bus did not do what was asked: one line
        print(f"bench_ethercat: {exc}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(figures))
    else:
        for key, value in figures.items():
            print(f"{key:>16}: {value}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
