"""Each pinocchio algorithm of the native dynamics timed inside C++ (no Python in the clock),
on the library hofto-hw builds (hofto_hw/model/native/dynamics.cpp, its ``hofto_dyn1_time``).

    python tools/bench_native.py [--config configs/er3a.yaml] [--reps 31] [--json]

Samples: 256 random (q, qd, tau - f) of the config's arm (q uniform in ±3 rad, qd in ±2 rad/s,
torques in ±50 N·m), cycled; each figure is the median over ``reps`` passes of the mean time
of one call [ns → µs], warm caches. "terms" is what one snapshot call computes for the
terms the main job's observers ask for (HOFTO + momentum: M, g, Cᵀ·qd, the acceleration):
"shared" is the library's route (the acceleration by a Cholesky solve with CRBA's M and
nonLinearEffects' nle), "separate" one algorithm per term (ABA for the
acceleration: the library before).
Timing goals live here, never in tests.
"""

from __future__ import annotations

import argparse
import ctypes
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

#: hofto_dyn1_time's `which`
ALGORITHMS = {
    "aba": 0,
    "crba": 1,
    "coriolis matrix": 2,
    "gravity": 3,
    "nonlinear effects": 4,
    "cholesky decompose + solve": 5,
    "Cᵀ·qd by the momentum recursion (with its kinematics)": 8,
}


def measure(config: Path, reps: int, count: int = 256) -> dict:
    from hofto_hw.config import load_config
    from hofto_hw.model import native
    from hofto_hw.model.robot import RobotModel

    model = RobotModel.from_config(load_config(config).robot)
    nm = native.model_for(model)
    if nm is None:
        return {"error": native.unavailable_reason() or "native dynamics unavailable"}
    lib = native._LIB
    assert lib is not None
    p, i64 = ctypes.c_void_p, ctypes.c_int64
    time_of = lib.hofto_dyn1_time
    time_of.restype = ctypes.c_double
    time_of.argtypes = [p, i64, i64, i64, i64, p, p, p, p]
    n = model.n
    rng = np.random.default_rng(1)
    q = rng.uniform(-3.0, 3.0, (count, n))
    qd = rng.uniform(-2.0, 2.0, (count, n))
    total = rng.uniform(-50.0, 50.0, (count, n))
    out = np.zeros((n + 4, n))
    main_job = native.MASS | native.GRAVITY | native.CORIOLIS_T | native.ACCEL
    every = main_job | native.NLE

    def us(which: int, terms: int = 0) -> float:
        ns = time_of(
            nm.handle, which, terms, count, reps, q.ctypes.data, qd.ctypes.data,
            total.ctypes.data, out.ctypes.data,
        )  # fmt: skip
        return round(ns / 1000.0, 3)

    res: dict = {"config": str(config), "n": n, "samples": count, "reps": reps, "us": {}}
    figures = res["us"]
    for _rep in range(3):  # interleaved, median of three
        row = {name: us(which) for name, which in ALGORITHMS.items()}
        row["terms, main job (M, g, Cᵀ·qd, accel): shared"] = us(6, main_job)
        row["terms, main job (M, g, Cᵀ·qd, accel): separate (ABA, Coriolis matrix)"] = us(
            7, main_job
        )
        row["terms, all five: shared"] = us(6, every)
        row["terms, all five: separate (ABA, nonLinearEffects, Coriolis matrix)"] = us(7, every)
        for k, v in row.items():
            figures.setdefault(k, []).append(v)
    for k, v in figures.items():
        figures[k] = float(np.median(v))
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", type=Path, default=ROOT / "configs" / "er3a.yaml")
    ap.add_argument("--reps", type=int, default=31)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    res = measure(a.config, a.reps)
    if a.json:
        print(json.dumps(res, indent=2))
        return
    if "error" in res:
        print(f"bench_native: {res['error']}")
        return
    print(f"{res['config']}: {res['n']} axes, inside C++, median µs per call")
    for k, v in res["us"].items():
        print(f"  {k:58s} {v:7.3f}")


if __name__ == "__main__":
    main()
