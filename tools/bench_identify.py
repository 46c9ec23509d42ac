"""Time and peak memory of identification; prints a table or --json.

    .venv/bin/python tools/bench_identify.py [--repeats 3] [--json] [--no-replay]

Cases (simulated ER3A-class arm, configs/er3a.yaml, realistic noise, no contact):
- 50 s of 100 Hz data (5 000 samples), 60 s of 1 kHz data (60 000 samples);
each timed for conditioning (zero-phase filter, differentiation) plus ``identify`` with the
physically consistent method, and ``identify`` with OLS only. Figures are medians over
``--repeats`` runs; peak memory is the tracemalloc peak of one run (numpy buffers included).
Replay throughput comes from tools/bench_replay.py (UR10e parameters, its default recording).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hofto_hw.config.loader import load_config  # noqa: E402
from hofto_hw.config.models import SystemConfig  # noqa: E402
from hofto_hw.identify.data import Recording, condition  # noqa: E402
from hofto_hw.identify.excitation import trajectory_from_vector  # noqa: E402
from hofto_hw.identify.pipeline import Samples, identify  # noqa: E402
from hofto_hw.identify.simulate import simulate_tracking  # noqa: E402
from hofto_hw.model import RobotModel  # noqa: E402

CASES = {"50s@100Hz": (50.0, 100.0), "60s@1kHz": (60.0, 1000.0)}


def _recording(model: RobotModel, cfg: SystemConfig, duration: float, rate: float) -> Recording:
    rng = np.random.default_rng(0)
    X = rng.normal(0.0, 0.5, (6, 8)) / np.tile(np.arange(1, 5), 2)
    traj = trajectory_from_vector(np.hstack([model.home[:, None], X]).ravel(), 6, 5, 10.0)
    sim = cfg.simulation.model_copy(deep=True)
    sim.external = []
    return simulate_tracking(model, sim, traj, rate, duration).measured


def _identify(model: RobotModel, rec: Recording, method: str) -> None:
    cond = condition(rec, 10.0, trim=False, filter_torque=False)
    identify(model, [Samples(cond.q, cond.qd, cond.qdd, cond.tau, rec.source)], method=method)


def bench_case(model: RobotModel, rec: Recording, method: str, repeats: int) -> dict[str, float]:
    """Median seconds, samples/s and tracemalloc peak [MB] of conditioning + identification."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        _identify(model, rec, method)
        times.append(time.perf_counter() - t0)
    tracemalloc.start()
    _identify(model, rec, method)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    med = statistics.median(times)
    return {
        "seconds": med,
        "samples": rec.n_samples,
        "samples_per_s": rec.n_samples / med,
        "peak_mb": peak / 1e6,
    }


def replay_figures(repeats: int) -> dict[str, dict[str, float]] | str:
    """Replay throughput from tools/bench_replay.py, or why it is not available."""
    try:
        sys.path.insert(0, str(ROOT / "tools"))
        import bench_replay

        from hofto_hw.replay.session import load_for_replay
        from hofto_hw.replay.setup import load_setup
    except ImportError as exc:
        return f"not available: {exc}"
    setup = load_setup(ROOT / "configs/ur10e/parameters.yaml")
    rec = load_for_replay(setup, ROOT / "tests/data/ur10e/push_pose_1_rows100-600.csv", None)
    return bench_replay.replay_throughput(setup.model, rec, repeats=repeats)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--json", action="store_true")
    p.add_argument("--no-replay", action="store_true", help="skip the replay throughput")
    args = p.parse_args(argv)
    cfg = load_config(ROOT / "configs/er3a.yaml")
    model = RobotModel.from_config(cfg.robot)
    results: dict = {}
    for case, (duration, rate) in CASES.items():
        rec = _recording(model, cfg, duration, rate)
        for method in ("consistent", "ols"):
            results[f"{case} {method}"] = bench_case(model, rec, method, args.repeats)
    replay = None if args.no_replay else replay_figures(args.repeats)
    if args.json:
        print(json.dumps({"identify": results, "replay": replay}))
        return 0
    print(f"identification (ER3A sim), median of {args.repeats} runs")
    print(f"{'case':26s} {'samples':>8s} {'time [s]':>9s} {'samples/s':>10s} {'peak MB':>8s}")
    for name, r in results.items():
        print(
            f"{name:26s} {r['samples']:8d} {r['seconds']:9.2f} {r['samples_per_s']:10.0f} "
            f"{r['peak_mb']:8.1f}"
        )
    if isinstance(replay, dict):
        print("replay throughput (UR10e parameters, tools/bench_replay.py)")
        for name, r in replay.items():
            print(f"  {name:10s} {r['samples_per_s']:12.0f} samples/s {r['us_per_sample']:8.1f} µs")
    elif replay is not None:
        print(f"replay throughput: {replay}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
