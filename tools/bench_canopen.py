"""Benchmark the CANopen master against the emulated CANopen drives (six nodes).

Runs the cyclic exchange (RPDOs + SYNC, TPDOs against the per-cycle deadline) at the
highest rate the bus-load limit allows (or ``--rate``), drives enabled in CSP holding
position, and prints per case: cycles, partial cycles (missing/late TPDOs), late frames,
exchange time median / p99 / p99.9 [ms], cycle overruns, CPU % of the master process
(``--json`` also: non-ok cycles, backlogs written off after ``tpdo_resync``).

Cases: ``virtual`` (one process: emulator thread + master) and ``udp`` (two processes over
udp_multicast inside a private network namespace; root), each without and with SCHED_FIFO.

  python tools/bench_canopen.py [--quick] [--duration 60] [--rate HZ] [--json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "configs" / "er3a_canopen.yaml"
CHANNEL = "239.74.163.2"


def _fifo(priority: int = 50) -> bool:
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        return True
    except (PermissionError, OSError):
        return False


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def run_master(interface: str, channel: str, rate: float, duration: float, fifo: bool) -> dict:
    """Open, enable in CSP, cycle for ``duration`` s at ``rate`` Hz; figures as a dict."""
    from drivers.canopen.master import CANopenTransport
    from drivers.cia402.drive_group import DriveGroup
    from drivers.cia402.state_machine import Mode
    from hofto_hw.config.loader import load_config

    cfg = load_config(CONFIG)
    period = 1.0 / rate
    t = CANopenTransport(
        channel,
        cfg.bus.drives,
        period,
        list(cfg.robot.joints),
        can_interface=interface,
        heartbeat_timeout=0.5,
        boot_timeout=10.0,
        sdo_timeout=1.0,
    )
    with t:
        g = DriveGroup(t, DriveGroup.from_config(t, cfg.bus).scaling, transition_timeout=2.0)
        g.set_mode(Mode.CSP)
        g.enable()
        q_hold = g.q.copy()
        fifo_ok = _fifo() if fifo else False
        n = int(duration * rate)
        dt = np.empty(n)
        status = np.empty(n, dtype=np.int64)
        overruns = 0
        late0, partial0 = t.late_frames, t.partial_cycles
        resync0 = getattr(t, "resyncs", 0)
        cpu0, wall0 = _cpu(), time.monotonic()
        deadline = time.monotonic()
        for k in range(n):
            g.command_position(q_hold)
            a = time.perf_counter()
            status[k] = g.cycle()
            dt[k] = time.perf_counter() - a
            deadline += period
            delay = deadline - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            else:
                overruns += 1
                if -delay > 10 * period:
                    deadline = time.monotonic()
        cpu, wall = _cpu() - cpu0, time.monotonic() - wall0
    ms = dt * 1e3
    return {
        "rate_hz": rate,
        "cycles": n,
        "partial_cycles": int(t.partial_cycles - partial0),
        "late_frames": int(t.late_frames - late0),
        # backlogs written off (a TPDO lost on the way: stale cycles until tpdo_resync)
        "resyncs": int(getattr(t, "resyncs", 0) - resync0),
        "non_ok_cycles": int((status != 0).sum()),
        "exchange_ms_median": float(np.median(ms)),
        "exchange_ms_p99": float(np.percentile(ms, 99)),
        "exchange_ms_p99_9": float(np.percentile(ms, 99.9)),
        "exchange_ms_max": float(ms.max()),
        "overruns": overruns,
        "cpu_percent": 100.0 * cpu / wall,
        "sched_fifo": fifo_ok,
    }


def case_virtual(rate: float, duration: float, fifo: bool) -> dict:
    """Master and emulator thread in this process on python-can's virtual bus."""
    import can

    from drivers.sim.canopen_node import CanopenDrives
    from hofto_hw.config.loader import load_config
    from hofto_hw.runtime.build import build_emulated_drives as build_drives

    cfg = load_config(CONFIG)
    cfg = cfg.model_copy(update={"loop": cfg.loop.model_copy(update={"rate_hz": rate})})
    channel = f"bench-{os.getpid()}-{time.monotonic_ns()}"
    bus = can.Bus(interface="virtual", channel=channel)
    emu = CanopenDrives(build_drives(cfg, external=False), bus)
    if fifo:
        run = emu.run

        def run_fifo(duration: float | None = None) -> None:
            _fifo(60)
            run(duration)

        emu.run = run_fifo  # type: ignore[method-assign]
    emu.start()
    try:
        return run_master("virtual", channel, rate, duration, fifo)
    finally:
        emu.stop()
        bus.shutdown()


def case_udp(rate: float, duration: float, fifo: bool) -> dict:
    """Emulator (hofto-hw sim-canopen) and master in two processes, udp_multicast, netns."""
    if os.geteuid() != 0:
        return {"skipped": "needs root for a private network namespace"}
    ns = f"hcanb{os.getpid()}"
    ip = ["ip", "netns", "exec", ns]
    subprocess.run(["ip", "netns", "add", ns], check=True)
    tmp = Path(tempfile.mkdtemp())
    try:
        subprocess.run([*ip, "ip", "link", "set", "lo", "up"], check=True)
        subprocess.run([*ip, "ip", "route", "add", "224.0.0.0/4", "dev", "lo"], check=True)
        chrt = ["chrt", "-f", "60"] if fifo else []
        cfg_path = tmp / "bench.yaml"
        cfg_path.write_text(
            CONFIG.read_text()
            .replace("rate_hz: 200.0", f"rate_hz: {rate}")
            .replace("urdf: er3a/er3a.urdf", f"urdf: {CONFIG.parent / 'er3a' / 'er3a.urdf'}")
        )
        env = dict(os.environ, PYTHONPATH=str(ROOT))
        ready = tmp / "ready"
        emu = subprocess.Popen(
            [
                *ip,
                *chrt,
                sys.executable,
                "-m",
                "hofto_hw.cli",
                "sim-canopen",
                "--interface",
                "udp_multicast",
                "--channel",
                CHANNEL,
                "--config",
                str(cfg_path),
                "--quiet-arm",
                "--ready-file",
                str(ready),
            ],
            cwd=ROOT,
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        try:
            end = time.monotonic() + 30
            while not ready.exists() and time.monotonic() < end and emu.poll() is None:
                time.sleep(0.02)
            master = subprocess.run(
                [
                    *ip,
                    *chrt,
                    sys.executable,
                    str(Path(__file__)),
                    "--role",
                    "master",
                    "--rate",
                    str(rate),
                    "--duration",
                    str(duration),
                ]
                + (["--fifo"] if fifo else []),
                cwd=ROOT,
                env=env,
                capture_output=True,
                text=True,
                timeout=duration + 120,
            )
            if master.returncode != 0:
                return {"error": master.stderr.strip().splitlines()[-1:]}
            return json.loads(master.stdout.strip().splitlines()[-1])
        finally:
            emu.send_signal(signal.SIGTERM)
            emu.wait(10)
    finally:
        subprocess.run(["ip", "netns", "del", ns], check=False)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--duration", type=float, default=60.0, help="seconds per case")
    p.add_argument("--quick", action="store_true", help="3 s per case")
    p.add_argument("--rate", type=float, default=None, help="Hz (default: highest feasible)")
    p.add_argument("--cases", default="virtual,udp", help="comma list of virtual, udp")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument("--role", default=None, help=argparse.SUPPRESS)
    p.add_argument("--fifo", action="store_true", help=argparse.SUPPRESS)
    a = p.parse_args()
    if a.role == "master":
        print(json.dumps(run_master("udp_multicast", CHANNEL, a.rate, a.duration, a.fifo)))
        return
    from drivers.canopen.busload import configured_load
    from hofto_hw.config.loader import load_config

    cfg = load_config(CONFIG)
    load = configured_load(cfg.bus, cfg.loop.rate_hz)
    rate = a.rate or float(math.floor(load.highest_rate() / 10.0) * 10)
    duration = 3.0 if a.quick else a.duration
    results: dict[str, Any] = {
        "rate_hz": rate,
        "bus_load_percent": 100 * load.seconds_per_cycle * rate,
        "duration_s": duration,
    }
    for case in a.cases.split(","):
        for fifo in (False, True):
            fn = {"virtual": case_virtual, "udp": case_udp}[case]
            results[f"{case}{'_fifo' if fifo else ''}"] = fn(rate, duration, fifo)
    if a.json:
        print(json.dumps(results, indent=2))
        return
    print(
        f"six CANopen nodes at {rate:g} Hz (worst-case bus load "
        f"{results['bus_load_percent']:.0f} % of 1 Mbit/s), {duration:g} s per case"
    )
    head = (
        f"{'case':14s} {'cycles':>7s} {'partial':>7s} {'late fr':>7s} {'median':>7s} "
        f"{'p99':>7s} {'p99.9':>7s} {'max':>7s} {'overrun':>7s} {'CPU %':>6s}"
    )
    print(head)
    for key, r in results.items():
        if not isinstance(r, dict):
            continue
        if "cycles" not in r:
            print(f"{key:14s} {r}")
            continue
        print(
            f"{key:14s} {r['cycles']:7d} {r['partial_cycles']:7d} {r['late_frames']:7d} "
            f"{r['exchange_ms_median']:7.3f} {r['exchange_ms_p99']:7.3f} "
            f"{r['exchange_ms_p99_9']:7.3f} {r['exchange_ms_max']:7.3f} {r['overruns']:7d} "
            f"{r['cpu_percent']:6.1f}"
        )
    print("exchange times in ms (RPDOs + SYNC sent, all TPDOs received)")


if __name__ == "__main__":
    main()
