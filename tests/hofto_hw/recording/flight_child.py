"""A stand-in for the loop process in the recorder tests: pushes tick records at ~1 kHz on
absolute deadlines into a FlightRecorder and reports progress on stdout.

    python flight_child.py OUT.mcap N_TICKS   # N_TICKS = 0: push until killed

Prints ``ready WRITER_PID SHM_NAME`` once the writer has opened the file, then
``pushed K FLUSHED T`` every 100 ticks (T: the tick time [s]) and ``done K`` after N_TICKS;
SIGTERM closes the recorder, prints ``closed <health as JSON>`` and exits 0. Tick k carries
q = k·1e-3 + j (joint j), so a reader can check every value.
"""

from __future__ import annotations

import json
import signal
import sys
import time
from dataclasses import asdict
from pathlib import Path

from hofto_hw.recording.flight_file import LogSpec
from hofto_hw.recording.record import EVENT_DTYPE, new_record
from hofto_hw.recording.recorder import FlightRecorder

JOINTS = [f"joint_{j + 1}" for j in range(6)]
OBSERVERS = ["hofto", "momentum", "eso"]
ATTACHMENTS = [
    ("config.yaml", "application/yaml", b"robot: {name: test}\n"),
    ("parameters.yaml", "application/yaml", b"format: params\n"),
    ("thresholds.yaml", "application/yaml", b"format: thresholds\n"),
]


def fill(rec, k: int) -> None:
    """Tick k's values (see the module docstring)."""
    rec["t"] = k * 1e-3
    rec["tick"] = k
    for j in range(6):
        rec["q"][j] = k * 1e-3 + j
    rec["qd"][:] = 0.5
    rec["tau"][:] = -1.0
    rec["tau_ext"][:] = 0.25
    rec["faults"] = k % 7
    rec["wakeup_us"] = 1.5


def main() -> int:
    out, n_ticks = Path(sys.argv[1]), int(sys.argv[2])
    spec = LogSpec(out, JOINTS, OBSERVERS, attachments=ATTACHMENTS, event_kinds={1: "collision"})
    rec = FlightRecorder(spec).start()
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    print(f"ready {rec.writer_pid} {rec.shm_name}", flush=True)
    tick = new_record(rec.tick_dtype)
    ev = new_record(EVENT_DTYPE)
    k = 0
    deadline = time.monotonic()
    while not stop and (n_ticks == 0 or k < n_ticks):
        fill(tick, k)
        rec.push_tick(tick)
        if k == 500:
            ev["t"], ev["tick"], ev["kind"], ev["joint"], ev["category"] = k * 1e-3, k, 1, 2, 1
            rec.push_event(ev)
        k += 1
        if k % 100 == 0:
            print(f"pushed {k} {rec.health().records_flushed} {k * 1e-3}", flush=True)
        deadline += 1e-3
        delay = deadline - time.monotonic()
        if delay > 0:
            time.sleep(delay)
    print(f"done {k}", flush=True)
    while not stop:
        time.sleep(0.01)
    health = rec.close()
    print("closed " + json.dumps(asdict(health), default=str), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
