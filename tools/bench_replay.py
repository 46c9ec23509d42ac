"""Replay throughput (samples/s) per observer on a recording; prints a table or --json.

    .venv/bin/python tools/bench_replay.py [--params P] [--file F] [--repeats 5] [--json]

Default recording: tests/data/ur10e/push_pose_1_rows100-600.csv with the UR10e parameters.
``replay_throughput`` is importable (tools/bench_identify.py uses it). Figures are medians
over ``repeats`` runs; the monitor is timed separately (per sample, with thresholds).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hofto_hw.config.collision import CollisionConfig  # noqa: E402
from hofto_hw.identify.data import Recording  # noqa: E402
from hofto_hw.model import RobotModel  # noqa: E402
from hofto_hw.observers import make_observer  # noqa: E402
from hofto_hw.replay.defaults import OBSERVER_NAMES, default_observer  # noqa: E402
from hofto_hw.replay.runner import run_monitor, run_observer  # noqa: E402
from safety.collision import CollisionMonitor  # noqa: E402


def replay_throughput(
    model: RobotModel,
    rec: Recording,
    observers: tuple[str, ...] = OBSERVER_NAMES,
    repeats: int = 5,
) -> dict[str, dict[str, float]]:
    """Per observer: median samples/s and µs per sample of a causal replay over ``rec``;
    key ``monitor`` times the collision monitor alone."""
    out: dict[str, dict[str, float]] = {}
    n = rec.n_samples
    for name in observers:
        obs = make_observer(default_observer(name, model.n), model)
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            est = run_observer(rec, obs)
            times.append(time.perf_counter() - t0)
        med = statistics.median(times)
        out[name] = {"samples_per_s": n / med, "us_per_sample": 1e6 * med / n}
    mon = CollisionMonitor(
        CollisionConfig(
            base=[10.0] * model.n,
            velocity_gain=[1.0] * model.n,
            acceleration_gain=[1.0] * model.n,
            reversal_margin=[5.0] * model.n,
        )
    )
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        run_monitor(rec, est, mon)
        times.append(time.perf_counter() - t0)
    med = statistics.median(times)
    out["monitor"] = {"samples_per_s": n / med, "us_per_sample": 1e6 * med / n}
    return out


def main(argv: list[str] | None = None) -> int:
    from hofto_hw.replay.session import load_for_replay
    from hofto_hw.replay.setup import load_setup

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--params", type=Path, default=ROOT / "configs/ur10e/parameters.yaml")
    p.add_argument(
        "--file", type=Path, default=ROOT / "tests/data/ur10e/push_pose_1_rows100-600.csv"
    )
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    setup = load_setup(args.params)
    rec = load_for_replay(setup, args.file, None)
    res = replay_throughput(setup.model, rec, repeats=args.repeats)
    if args.json:
        print(json.dumps({"file": str(args.file), "samples": rec.n_samples, "results": res}))
        return 0
    print(f"{args.file.name}: {rec.n_samples} samples, median of {args.repeats} runs")
    print(f"{'observer':10s} {'samples/s':>12s} {'µs/sample':>10s}")
    for name, r in res.items():
        print(f"{name:10s} {r['samples_per_s']:12.0f} {r['us_per_sample']:10.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
