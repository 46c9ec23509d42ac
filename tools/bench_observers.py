"""Cost of one observer update for six axes, model calls included, next to the bare
pinocchio calls as the floor.

    python tools/bench_observers.py [--ticks 100000] [--config configs/er3a.yaml] [--json]

Each update is timed alone with perf_counter_ns over ``--ticks`` ticks (inputs cycle
through 1000 precomputed samples of a moving arm); the figures are the median and the 99th
percentile in µs. Garbage collection is off while timing, as in the real-time loop. The
machine's noise shows in p99: compare medians and ratios, not single runs.
"""

from __future__ import annotations

import argparse
import gc
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def time_calls(fn, inputs, ticks: int) -> np.ndarray:
    """Per-call durations [µs] of fn(*inputs[k % len]) over ``ticks`` calls."""
    n = len(inputs)
    out = np.empty(ticks)
    clock = time.perf_counter_ns
    for k in range(min(ticks, 2000)):  # warm up caches and branch predictors
        fn(*inputs[k % n])
    gc.disable()
    try:
        for k in range(ticks):
            args = inputs[k % n]
            t0 = clock()
            fn(*args)
            out[k] = clock() - t0
    finally:
        gc.enable()
    return out / 1000.0


def main(argv: list[str] | None = None) -> int:
    import pinocchio as pin

    from hofto_hw.config import load_config
    from hofto_hw.model import RobotModel
    from hofto_hw.observers import make_observer

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", type=Path, default=ROOT / "configs" / "er3a.yaml")
    parser.add_argument("--ticks", type=int, default=100_000)
    parser.add_argument("--json", action="store_true")
    parser.add_argument(
        "--backend",
        choices=("python", "numba", "auto"),
        default="auto",
        help="observer path (python: the kernels' source run by the interpreter)",
    )
    args = parser.parse_args(argv)

    cfg = load_config(args.config)
    model = RobotModel.from_config(cfg.robot)
    rng = np.random.default_rng(0)
    t = np.arange(1000) * 1e-3
    q = model.home + 0.3 * np.sin(np.outer(t, rng.uniform(0.5, 3.0, model.n)))
    qd = np.gradient(q, 1e-3, axis=0)
    data = model.create_data()
    tau = np.array([data.gravity(x).copy() for x in q]) + rng.normal(0, 1, q.shape)
    dt = 1.0 / cfg.loop.rate_hz
    samples = [(q[k].copy(), qd[k].copy(), tau[k].copy()) for k in range(len(t))]

    m, d = model.pin_model, data.pin_data
    floor = {
        "pin.crba": lambda q_, qd_, tau_: pin.crba(m, d, q_),
        "pin.aba": lambda q_, qd_, tau_: pin.aba(m, d, q_, qd_, tau_),
        "pin.nonLinearEffects": lambda q_, qd_, tau_: pin.nonLinearEffects(m, d, q_, qd_),
        "pin.computeCoriolisMatrix": lambda q_, qd_, tau_: pin.computeCoriolisMatrix(m, d, q_, qd_),
        "model terms of HOFTO (M⁻¹ via ABA + friction, M(q) symmetric, M·z3)": None,
    }
    z3 = np.zeros(model.n)
    out6 = np.zeros(model.n)

    def hofto_model_terms(q_, qd_, tau_):
        data.forward_dynamics(q_, qd_, tau_)
        np.dot(data.mass_matrix(q_), z3, out=out6)

    floor["model terms of HOFTO (M⁻¹ via ABA + friction, M(q) symmetric, M·z3)"] = hofto_model_terms

    results: dict[str, dict[str, float]] = {}
    for name, fn in floor.items():
        us = time_calls(fn, samples, args.ticks)
        results[name] = {"median_us": float(np.median(us)), "p99_us": float(np.percentile(us, 99))}
    for name, ocfg in cfg.observers.items():
        obs = make_observer(ocfg, model, backend=args.backend)
        obs.reset(q[0], qd[0])
        us = time_calls(lambda a, b, c, o=obs: o.update(a, b, c, dt), samples, args.ticks)
        label = f"observer {name} ({ocfg.type}" + (
            f", n = {ocfg.order}, {ocfg.form}, substeps {ocfg.substeps})"
            if ocfg.type == "hofto"
            else ")"
        )
        results[label] = {
            "median_us": float(np.median(us)),
            "p99_us": float(np.percentile(us, 99)),
        }

    meta = {
        "ticks": args.ticks,
        "config": str(args.config),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "pinocchio": pin.__version__,
        "machine": platform.machine(),
        "target": "HOFTO (n = 2) with its model calls <= 40 µs median",
    }
    if args.json:
        print(json.dumps({"meta": meta, "results": results}, indent=2))
        return 0
    print(
        f"observer update cost, {args.ticks} ticks each, six axes ({meta['machine']}, "
        f"python {meta['python']}, numpy {meta['numpy']}, pinocchio {meta['pinocchio']})"
    )
    print(f"{'':72}{'median µs':>10}{'p99 µs':>10}")
    for name, r in results.items():
        print(f"{name:<72}{r['median_us']:10.2f}{r['p99_us']:10.2f}")
    print(f"target: {meta['target']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
