"""Flight-recorder benchmark: push cost, writer throughput, and what the recorder does to the
wake-up latency of a bare 1 kHz absolute-deadline loop (recorder off / writer process /
writer thread in the loop's process, the design the issue measured at p99 3.1 ms).

    python tools/bench_recorder.py            # ~40 s
    python tools/bench_recorder.py --quick    # ~10 s
    python tools/bench_recorder.py --json --fifo   # SCHED_FIFO 50 for the loop (root)
    python tools/bench_recorder.py --fifo --pin    # loop on the last CPU, writer elsewhere

Figures: push median/p99 [µs]; JointState encoding cost per message; writer messages/s
and tick records/s (6 joints, 3 observers: 7 messages per tick); loop wake-up latency
median/p99/p99.9/max [µs] and overruns (> 1 ms late) for each mode; dropped records.
"""

from __future__ import annotations

import argparse
import ctypes
import gc
import json
import os
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from hofto_hw.recording.flight_file import FlightFile, LogSpec
from hofto_hw.recording.record import DIAG_DTYPE, new_record, tick_dtype
from hofto_hw.recording.recorder import FlightRecorder
from hofto_hw.recording.ring import Ring, ring_nbytes
from hofto_hw.recording.shared import Capacities

JOINTS = [f"joint_{j + 1}" for j in range(6)]
OBSERVERS = ["hofto", "momentum", "eso"]


class _Timespec(ctypes.Structure):
    _fields_ = [("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long)]


_libc = ctypes.CDLL(None, use_errno=True)
_CLOCK_MONOTONIC, _TIMER_ABSTIME = 1, 1


def sleep_until(deadline_ns: int, ts: _Timespec) -> None:
    """clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME) to ``deadline_ns`` [ns]."""
    ts.tv_sec, ts.tv_nsec = divmod(deadline_ns, 1_000_000_000)
    _libc.clock_nanosleep(_CLOCK_MONOTONIC, _TIMER_ABSTIME, ctypes.byref(ts), None)


def fill(rec: np.ndarray, k: int, rng: np.random.Generator) -> None:
    rec["t"], rec["tick"] = k * 1e-3, k
    rec["q"][:] = rng.normal(size=6)
    rec["qd"][:] = rng.normal(size=6)
    rec["tau"][:] = rng.normal(size=6)
    rec["q_cmd"][:] = rec["q"]
    rec["tau_ext"][:] = rng.normal(size=(3, 6))
    rec["wrench"][:] = rng.normal(size=6)


def stats_us(ns: np.ndarray) -> dict[str, float]:
    us = np.asarray(ns, dtype=float) / 1e3
    return {
        "median": float(np.median(us)),
        "p99": float(np.percentile(us, 99)),
        "p999": float(np.percentile(us, 99.9)),
        "max": float(us.max()),
    }


def spec(folder: Path, name: str) -> LogSpec:
    return LogSpec(folder / name, JOINTS, OBSERVERS, wrench_frame="tool0")


def bench_push(folder: Path, n: int) -> dict[str, float]:
    """Cost of FlightRecorder.push_tick with the writer process running."""
    rec = FlightRecorder(spec(folder, "push.mcap"), Capacities(tick=1 << 15)).start()
    tick = new_record(rec.tick_dtype)
    fill(tick, 0, np.random.default_rng(0))
    times = np.zeros(n, dtype=np.int64)
    clock = time.perf_counter_ns
    for k in range(n):
        tick["tick"] = k
        t0 = clock()
        rec.push_tick(tick)
        times[k] = clock() - t0
        if k % 1000 == 999:
            time.sleep(0.05)  # let the writer drain (this measures the push, not the drain)
    health = rec.close()
    return {**stats_us(times), "dropped": health.dropped}


def bench_encode(n: int) -> dict[str, float]:
    """Per-message cost of a JointState [µs]: mcap_ros2's dict encoder vs a fixed-layout
    batch (what the writer does), both to bytes."""
    from mcap_ros2._dynamic import serialize_dynamic

    from hofto_hw.recording import cdr
    from hofto_hw.recording import schemas as s

    rng = np.random.default_rng(3)
    q = rng.normal(size=(n, 6))
    enc = serialize_dynamic(s.JOINT_STATE_TYPE, s.JOINT_STATE_MSGDEF)[s.JOINT_STATE_TYPE]
    t0 = time.perf_counter()
    for k in range(n):
        enc(
            {
                "header": {"stamp": {"sec": 0, "nanosec": k}, "frame_id": ""},
                "name": JOINTS,
                "position": q[k].tolist(),
                "velocity": q[k].tolist(),
                "effort": q[k].tolist(),
            }
        )
    dict_us = (time.perf_counter() - t0) / n * 1e6
    dtype, template = cdr.joint_state_layout(JOINTS, position=True, velocity=True, effort=True)
    t0 = time.perf_counter()
    for start in range(0, n, 100):  # batches of 100 (0.1 s at 1 kHz), as the writer drains
        b = cdr.fill_batch(dtype, template, 100)
        cdr.set_stamps(b, np.arange(100) * 1e-3)
        b["position"] = b["velocity"] = b["effort"] = q[start : start + 100]
        raw = b.tobytes()
        _ = [raw[i * dtype.itemsize : (i + 1) * dtype.itemsize] for i in range(100)]
    batch_us = (time.perf_counter() - t0) / n * 1e6
    return {"mcap_ros2_dict": dict_us, "fixed_layout_batch": batch_us}


def bench_writer(folder: Path, n_ticks: int) -> dict[str, float]:
    """Writer throughput: ticks already queued, drained as fast as the writer process goes."""
    rec = FlightRecorder(spec(folder, "throughput.mcap"), Capacities(tick=1 << 16)).start()
    tick = new_record(rec.tick_dtype)
    rng = np.random.default_rng(1)
    t0 = time.perf_counter()
    for k in range(n_ticks):
        fill(tick, k, rng)
        rec.push_tick(tick)
    while rec.health().records_written < n_ticks and rec.health().writer_alive:
        time.sleep(0.002)
    elapsed = time.perf_counter() - t0
    health = rec.close()
    per_tick = 4 + len(OBSERVERS)  # joint states, commands, status, wrench, observers
    return {
        "ticks_per_s": n_ticks / elapsed,
        "messages_per_s": n_ticks * per_tick / elapsed,
        "bytes_per_tick": health.bytes_written / n_ticks,
        "dropped": health.dropped,
    }


def bench_file_cost(folder: Path, n_ticks: int) -> dict[str, float]:
    """The writer's work per tick [µs] in this process (no ring, no process scheduling): the
    log's messages without and with the arm's topics (/tf at 50 Hz by pinocchio, the URDF)."""
    urdf = Path(__file__).resolve().parents[1] / "configs" / "er3a" / "er3a.urdf"
    rng = np.random.default_rng(2)
    ticks = np.zeros(n_ticks, dtype=tick_dtype(len(JOINTS), len(OBSERVERS)))
    for k in range(n_ticks):
        fill(ticks[k : k + 1].reshape(()), k, rng)
    runs: dict[str, list[float]] = {"without_arm_topics": [], "with_arm_topics": []}
    arm = [("robot.urdf", "application/xml", urdf.read_bytes())]
    for rep in range(5):  # alternated, medians: the machine is shared
        for label, attachments in (("without_arm_topics", []), ("with_arm_topics", arm)):
            s = LogSpec(folder / f"{label}{rep}.mcap", JOINTS, OBSERVERS,
                        attachments=attachments, tool_frame="tool0")  # fmt: skip
            f = FlightFile(s, s.path, 0)
            t0 = time.perf_counter()
            for start in range(0, n_ticks, 100):  # 0.1 s batches at 1 kHz, as the writer drains
                f.write_ticks(ticks[start : start + 100])
            f.finish()
            runs[label].append((time.perf_counter() - t0) / n_ticks * 1e6)
    return {label: float(np.median(v)) for label, v in runs.items()}


class _ThreadWriter:
    """The rejected design, for comparison: the same file writer in a thread of the loop."""

    def __init__(self, s: LogSpec) -> None:
        dtype = tick_dtype(len(JOINTS), len(OBSERVERS))
        self.buf = memoryview(bytearray(ring_nbytes(dtype, 1 << 14)))
        self.ring = Ring(self.buf, 0, dtype, 1 << 14, init=True)
        self.file = FlightFile(s, s.path, 0)
        self.stop = False
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        last = time.monotonic()
        while not self.stop:
            batch = self.ring.drain()
            if len(batch):
                self.file.write_ticks(batch)
            if time.monotonic() - last > 0.25:
                self.file.flush()
                last = time.monotonic()
            time.sleep(0.005)

    def push_tick(self, rec: np.ndarray) -> None:
        self.ring.push(rec)

    def push_diag(self, rec: np.ndarray) -> None:
        pass

    @property
    def dropped(self) -> int:
        return self.ring.dropped

    def close(self) -> None:
        self.stop = True
        self.thread.join()
        self.file.finish()


def bench_loop(folder: Path, mode: str, seconds: float, fifo: bool, pin: bool) -> dict[str, object]:
    """A bare 1 kHz loop (absolute deadlines, gc off) pushing one tick per cycle. ``pin``:
    the loop on the last CPU, the writer process on the others."""
    sink: object | None = None
    cpus = sorted(os.sched_getaffinity(0))
    old_affinity = set(cpus)
    if pin and len(cpus) > 1:
        os.sched_setaffinity(0, {cpus[-1]})
    if mode == "process":
        writer_cpus = cpus[:-1] if pin and len(cpus) > 1 else None
        sink = FlightRecorder(spec(folder, "loop.mcap"), cpus=writer_cpus).start()
    elif mode == "thread":
        sink = _ThreadWriter(spec(folder, "loop_thread.mcap"))
    tick = new_record(tick_dtype(len(JOINTS), len(OBSERVERS)))
    diag = new_record(DIAG_DTYPE)
    fill(tick, 0, np.random.default_rng(2))
    n = int(seconds * 1000)
    late = np.zeros(n, dtype=np.int64)
    old_policy = os.sched_getscheduler(0)
    if fifo:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(50))
    gc.collect()
    gc.disable()
    ts = _Timespec()
    period = 1_000_000
    deadline = time.monotonic_ns() + period
    try:
        for k in range(n):
            sleep_until(deadline, ts)
            late[k] = time.monotonic_ns() - deadline
            if sink is not None:
                tick["tick"] = k
                tick["t"] = k * 1e-3
                sink.push_tick(tick)  # type: ignore[attr-defined]
                if k % 100 == 0:
                    sink.push_diag(diag)  # type: ignore[attr-defined]
            deadline += period
            if late[k] > period:  # overrun: skip the missed cycles, as the loop does
                deadline += (late[k] // period) * period
    finally:
        gc.enable()
        if fifo:
            os.sched_setscheduler(0, old_policy, os.sched_param(0))
        os.sched_setaffinity(0, old_affinity)
    dropped = 0
    if sink is not None:
        dropped = sink.dropped  # type: ignore[attr-defined]
        sink.close()  # type: ignore[attr-defined]
    return {**stats_us(late), "overruns": int((late > period).sum()), "dropped": dropped}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print figures as JSON")
    parser.add_argument("--quick", action="store_true", help="short runs (~10 s)")
    parser.add_argument("--fifo", action="store_true", help="SCHED_FIFO 50 for the loop")
    parser.add_argument(
        "--pin", action="store_true", help="loop on the last CPU, writer on the others"
    )
    parser.add_argument("--seconds", type=float, help="seconds per loop mode (default 10/3)")
    args = parser.parse_args()
    seconds = args.seconds or (3.0 if args.quick else 10.0)
    out: dict[str, object] = {"loop_seconds": seconds, "fifo": args.fifo, "pin": args.pin}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        out["push_us"] = bench_push(folder, 5000 if args.quick else 20000)
        out["encode_us_per_message"] = bench_encode(2000 if args.quick else 10000)
        out["writer"] = bench_writer(folder, 10000 if args.quick else 30000)
        out["writer_us_per_tick"] = bench_file_cost(folder, 5000 if args.quick else 20000)
        out["loop_wakeup_us"] = {
            mode: bench_loop(folder, mode, seconds, args.fifo, args.pin)
            for mode in ("off", "process", "thread")
        }
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    p = out["push_us"]
    print(f"push_tick: median {p['median']:.2f} µs, p99 {p['p99']:.2f} µs")  # type: ignore[index]
    e = out["encode_us_per_message"]
    print(
        f"JointState encoding: mcap_ros2 {e['mcap_ros2_dict']:.1f} µs/message, "  # type: ignore[index]
        f"fixed-layout batch {e['fixed_layout_batch']:.2f} µs/message"  # type: ignore[index]
    )
    w = out["writer"]
    print(
        f"writer process: {w['ticks_per_s']:.0f} ticks/s = {w['messages_per_s']:.0f} "  # type: ignore[index]
        f"messages/s, {w['bytes_per_tick']:.0f} B/tick on disk"  # type: ignore[index]
    )
    c = out["writer_us_per_tick"]
    print(
        f"writer work per tick: {c['without_arm_topics']:.1f} µs, with /tf and the URDF "  # type: ignore[index]
        f"{c['with_arm_topics']:.1f} µs"  # type: ignore[index]
    )
    fifo = ("SCHED_FIFO 50" if args.fifo else "SCHED_OTHER") + (", pinned" if args.pin else "")
    print(f"1 kHz loop wake-up latency [µs], {seconds:.0f} s each, {fifo}:")
    for mode, r in out["loop_wakeup_us"].items():  # type: ignore[union-attr]
        print(
            f"  recorder {mode:8s} median {r['median']:7.1f}  p99 {r['p99']:7.1f}  "
            f"p99.9 {r['p999']:7.1f}  max {r['max']:8.1f}  overruns {r['overruns']}  "
            f"dropped {r['dropped']}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
