"""What the Foxglove live view costs the loop: `hofto-hw run --clock real` on the simulated arm,
quiet (live view off) against live view on with a client subscribed to every topic, alternated.

    python tools/bench_live_view.py                 # 3 pairs of 8 s runs
    python tools/bench_live_view.py --json --runs 5 --seconds 10

Figures per mode (medians over the runs): overruns (missed deadlines), wake-up latency
p99/max [µs], compute p99 [µs] (from --summary-json), messages the client received per second.
The live side runs in the flight recorder's writer process, never in the loop's, so the two
modes should not differ beyond the machine's noise.
"""

from __future__ import annotations

import argparse
import json
import os
import queue
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))


def _config(folder: Path, live: bool) -> Path:
    text = (ROOT / "configs" / "er3a.yaml").read_text()
    text = text.replace("urdf: er3a/er3a.urdf", f"urdf: {ROOT / 'configs/er3a/er3a.urdf'}")
    text = text.replace("  log_dir: ../out/logs", f"  log_dir: {folder}")
    if live:
        text = text.replace("\nrun:\n", "\nrun:\n  live_view: {host: 127.0.0.1, port: 0}\n", 1)
    path = folder / ("live.yaml" if live else "quiet.yaml")
    path.write_text(text)
    return path


def one_run(live: bool, seconds: float) -> dict[str, float]:
    """One run; with ``live`` a client subscribes to every topic for the whole run."""
    from support.foxglove_client import receive_topics

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        summary = folder / "summary.json"
        cmd = [sys.executable, "-m", "hofto_hw.cli", "run", "--config", str(_config(folder, live))]
        cmd += ["--clock", "real", "--duration", str(seconds), "--no-collision"]
        cmd += ["--summary-json", str(summary)]
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        proc = subprocess.Popen(
            cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
        )
        lines: queue.Queue[str] = queue.Queue()
        threading.Thread(
            target=lambda: [lines.put(x) for x in proc.stderr],
            daemon=True,  # type: ignore[union-attr]
        ).start()
        received = 0
        if live:
            url = None
            while url is None:
                m = re.search(r"live view on (ws://\S+)", lines.get(timeout=300))
                url = m.group(1) if m else None
            topics = ["/joint_states", "/joint_commands", "/loop/status", "/tf", "/diagnostics",
                      "/observers/hofto/tau_ext", "/observers/momentum/tau_ext",
                      "/tool/wrench_estimate", "/safety/events", "/robot_description"]  # fmt: skip
            t0 = time.monotonic()
            got = receive_topics(url, topics, dict.fromkeys(topics, 10**9), seconds)
            received = sum(len(v) for v in got.messages.values()) / (time.monotonic() - t0)
        rc = proc.wait(seconds + 300)
        if rc != 0:
            proc.send_signal(signal.SIGTERM)
            raise SystemExit(f"hofto-hw run exited {rc}")
        s = json.loads(summary.read_text())
    t = s["timing_us"]
    return {
        "overruns": s["overruns"],
        "wakeup_p99_us": t["wakeup"]["p99"],
        "wakeup_max_us": t["wakeup"]["max"],
        "compute_p99_us": t["compute"]["p99"],
        "overrun_latched": float("overrun" in s["latched"]),
        "client_messages_per_s": received,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print figures as JSON")
    parser.add_argument("--runs", type=int, default=3, help="runs per mode (alternated)")
    parser.add_argument("--seconds", type=float, default=8.0, help="run time [s]")
    args = parser.parse_args()
    runs: dict[str, list[dict[str, float]]] = {"quiet": [], "live_view": []}
    for _ in range(args.runs):
        runs["quiet"].append(one_run(False, args.seconds))
        runs["live_view"].append(one_run(True, args.seconds))
    out = {
        mode: {k: float(np.median([r[k] for r in rs])) for k in rs[0]} for mode, rs in runs.items()
    }
    out["runs"] = runs  # type: ignore[assignment]
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    print(f"hofto-hw run --clock real, {args.seconds:.0f} s, medians of {args.runs} runs:")
    for mode in ("quiet", "live_view"):
        r = out[mode]
        print(
            f"  {mode:9s} overruns {r['overruns']:5.0f}  wake-up p99 {r['wakeup_p99_us']:6.0f} µs"
            f"  max {r['wakeup_max_us']:7.0f} µs  compute p99 {r['compute_p99_us']:6.0f} µs"
            f"  client {r['client_messages_per_s']:6.0f} msg/s"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
