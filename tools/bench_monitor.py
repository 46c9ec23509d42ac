"""Per-update cost of the collision monitor (safety/collision/), its kernels as Python vs compiled.

    .venv/bin/python tools/bench_monitor.py [--ticks 20000] [--quick] [--json]

Cases (six joints): ``loop`` = the loop's monitor from configs/er3a.yaml ``safety.collision``
(contact + collision levels, hofto + momentum rows) through ``update(stop, ...)`` as the tick
calls it; ``loop_mean`` the same with ``logic: mean`` and full threshold terms;
``thresholds`` = the one-row CollisionMonitor of configs/ur10e/thresholds.yaml (momentum) as
replay calls it; ``tool_force`` = ``loop`` with the tool-force limit on (the loop cases include
the stop controller's begin_tick and its reports, as in the tick). Inputs: a slow motion
with noise and occasional contacts (trips and releases happen). Prints median / p99 [µs] per
update, the allocation per update (tracemalloc, bytes of growth over all updates) and the
compile time of the kernel. Figures only: no timing is asserted anywhere.
"""

from __future__ import annotations

import argparse
import gc
import json
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hofto_hw import jit  # noqa: E402
from hofto_hw.config import load_config  # noqa: E402
from hofto_hw.model import RobotModel  # noqa: E402
from hofto_hw.replay.thresholds import read_thresholds  # noqa: E402
from safety.collision import COLLIDED, CollisionLevels, CollisionMonitor  # noqa: E402
from safety.stop import StopController  # noqa: E402

DT = 1e-3


def _inputs(ticks: int, n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    t = np.arange(ticks) * DT
    qd = 0.4 * np.sin(np.outer(t, rng.uniform(0.5, 2.0, n))) + rng.normal(0, 1e-3, (ticks, n))
    tau = rng.normal(0, 0.8, (ticks, 2, n))
    for a in range(500, ticks - 100, 1500):  # a contact every 1.5 s on both rows
        tau[a : a + 60, :, a % n] += 9.0
    qdd = rng.normal(0, 1.0, (ticks, n))
    return qd, tau, qdd


def _stats(ns: np.ndarray) -> dict[str, float]:
    us = ns / 1000.0
    return {"median": float(np.median(us)), "p99": float(np.percentile(us, 99))}


def _time(call, ticks: int) -> tuple[dict[str, float], int]:
    clock = time.perf_counter_ns
    out = np.zeros(ticks, dtype=np.int64)
    for k in range(min(ticks, 200)):  # warm caches and branches
        call(k)
    gc.disable()
    for k in range(ticks):
        t0 = clock()
        call(k)
        out[k] = clock() - t0
    gc.enable()
    tracemalloc.start()
    before = tracemalloc.get_traced_memory()[0]
    for k in range(min(ticks, 3000)):
        call(k)
    grown = tracemalloc.get_traced_memory()[1] - before
    tracemalloc.stop()
    return _stats(out), int(grown)


def _levels_case(cfg, model, backend: str, ticks: int, qd, tau, qdd, q) -> dict:
    t0 = time.perf_counter()
    mon = CollisionLevels(cfg, ["hofto", "momentum"], model, backend=backend)
    build_s = time.perf_counter() - t0
    stop = StopController.from_config(load_config(ROOT / "configs/er3a.yaml").safety.categories)
    trips = 0

    def call(k: int) -> None:
        nonlocal trips
        stop.begin_tick(k + 1)
        trips += mon.update(stop, tau[k], q, qd[k], qdd[k], DT) & COLLIDED

    stats, grown = _time(call, ticks)
    return {"backend": mon.backend, **stats, "alloc_bytes": grown, "build_s": build_s}


def _single_case(mcfg, backend: str, ticks: int, qd, tau) -> dict:
    mon = CollisionMonitor(mcfg, backend=backend)
    mon.reset(qd[0])
    row = tau[:, 1]

    def call(k: int) -> None:
        mon.update(row[k], qd[k], DT)

    stats, grown = _time(call, ticks)
    return {"backend": mon.backend, **stats, "alloc_bytes": grown}


def bench(ticks: int) -> dict:
    cfg = load_config(ROOT / "configs/er3a.yaml")
    model = RobotModel.from_config(cfg.robot)
    n = model.n
    qd, tau, qdd = _inputs(ticks, n)
    q = model.home.copy()
    col = cfg.safety.collision
    mean = col.model_copy(
        update={
            "observer": "both",
            "logic": "mean",
            "acceleration_gain": [0.05] * n,
            "reversal_margin": [1.0] * n,
            "standstill_margin": [0.5] * n,
        }
    )
    tool = col.model_copy(update={"tool_force": 1e6})
    th = read_thresholds(ROOT / "configs/ur10e/thresholds.yaml")
    single = th.observers["momentum"].monitor
    backends = ["python"] + (["numba"] if jit.available() else [])
    res: dict = {"ticks": ticks, "compiled_available": jit.available(), "cases": {}}
    for name, make in (
        ("loop", lambda b: _levels_case(col, model, b, ticks, qd, tau, qdd, q)),
        ("loop_mean", lambda b: _levels_case(mean, model, b, ticks, qd, tau, qdd, q)),
        ("thresholds", lambda b: _single_case(single, b, ticks, qd, tau)),
        ("tool_force", lambda b: _levels_case(tool, model, b, ticks, qd, tau, qdd, q)),
    ):
        res["cases"][name] = {b: make(b) for b in backends}
    return res


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ticks", type=int, default=20000)
    ap.add_argument("--quick", action="store_true", help="2000 ticks per case")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    res = bench(2000 if args.quick else args.ticks)
    if args.json:
        print(json.dumps(res, indent=2))
        return 0
    print(f"collision monitor, six joints, {res['ticks']} updates per case [µs per update]")
    print(f"{'case':12s} {'backend':8s} {'median':>8s} {'p99':>8s} {'alloc B':>8s}")
    for name, per in res["cases"].items():
        for b, r in per.items():
            print(f"{name:12s} {b:8s} {r['median']:8.2f} {r['p99']:8.2f} {r['alloc_bytes']:8d}")
    if not res["compiled_available"]:
        print(f"compiled path unavailable: {jit.unavailable_reason()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
