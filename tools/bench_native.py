"""The native dynamics as the tick pays for it: the compiled kernels that call the library
(hofto_hw.model.kernels.snapshot_native and inverse_dynamics_native, one Python→compiled call
each), against pinocchio's Python calls that compute the same terms.

    python tools/bench_native.py [--config configs/er3a.yaml] [--reps 31] [--json]

Samples: 256 random (q, qd, tau) of the config's arm (q uniform in ±3 rad, qd in ±2 rad/s,
torques and accelerations in ±50), cycled. Each figure is the median over ``reps`` passes of
the mean time of one call [µs], back to back (warm caches; tools/bench_snapshot.py times the
same calls right after the simulated exchange, as in the tick); every pass times each variant
in turn, so that the machine's load hits all alike. The native calls include the snapshot's
finiteness check and friction (pinocchio's Python calls do not): one snapshot of each set of
terms an observer set asks for, each a route through dynamics.cpp. Timing goals live here,
never in tests.
"""

from __future__ import annotations

import argparse
import gc
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _calls(model, native) -> dict[str, Callable[[np.ndarray, np.ndarray, np.ndarray], object]]:  # type: ignore[no-untyped-def]
    """The variants by name, each f(q, qd, tau_or_qdd)."""
    import pinocchio as pin

    from hofto_hw.model import kernels as mk
    from hofto_hw.model.snapshot import DynamicsSnapshot, Needs

    pm = model.pin_model
    pd = pm.createData()
    aba, crba, gravity = pin.aba, pin.crba, pin.computeGeneralizedGravity
    coriolis, nle = pin.computeCoriolisMatrix, pin.nonLinearEffects

    def ct(q, qd):  # type: ignore[no-untyped-def]
        return coriolis(pm, pd, q, qd).T @ qd

    def main_job(q, qd, t):  # type: ignore[no-untyped-def]
        return aba(pm, pd, q, qd, t), crba(pm, pd, q), ct(q, qd), gravity(pm, pd, q)

    def all_five(q, qd, t):  # type: ignore[no-untyped-def]
        a, m, c, g = aba(pm, pd, q, qd, t), crba(pm, pd, q), ct(q, qd), gravity(pm, pd, q)
        return a, m, c, g, nle(pm, pd, q, qd)

    def hofto(q, qd, t):  # type: ignore[no-untyped-def]
        return aba(pm, pd, q, qd, t), crba(pm, pd, q)

    main = Needs.MASS | Needs.GRAVITY | Needs.CORIOLIS_T | Needs.ACCEL
    sets: dict[str, tuple[Needs, Callable]] = {
        "main job (M, g, Cᵀ·qd, accel)": (main, main_job),
        "all five (M, g, nle, Cᵀ·qd, accel)": (main | Needs.NLE, all_five),
        "HOFTO alone (M, accel)": (Needs.MASS | Needs.ACCEL, hofto),
        "Cᵀ·qd alone": (Needs.CORIOLIS_T, lambda q, qd, t: ct(q, qd)),
    }
    calls: dict[str, Callable] = {}
    for name, (needs, by_python) in sets.items():
        snap = DynamicsSnapshot(model, needs, "numba")
        if not snap.native:
            raise RuntimeError(f"the snapshot of {name} does not run the native library")
        (calls[f"snapshot {name}: native kernel"],) = snap.parts().values()
        calls[f"snapshot {name}: pinocchio Python"] = by_python
    W, out = mk.workspace(model.n), np.zeros(model.n)
    mk.pack_friction(model.friction, W)
    kernel, h = mk.inverse_dynamics_native, native.handle
    calls["feed-forward (RNEA + friction): native kernel"] = lambda q, qd, qdd: kernel(
        q, qd, qdd, W, out, h
    )
    calls["feed-forward (RNEA): pinocchio Python"] = lambda q, qd, qdd: pin.rnea(pm, pd, q, qd, qdd)
    calls["empty Python call"] = lambda q, qd, t: None
    return calls


def measure(config: Path, reps: int, count: int = 256) -> dict:
    from hofto_hw.config import load_config
    from hofto_hw.model import native
    from hofto_hw.model.robot import RobotModel

    model = RobotModel.from_config(load_config(config).robot)
    nm = native.model_for(model)
    if nm is None:
        return {"error": native.unavailable_reason() or "native dynamics unavailable"}
    calls = _calls(model, nm)
    n = model.n
    rng = np.random.default_rng(1)
    q = rng.uniform(-3.0, 3.0, (count, n))
    qd = rng.uniform(-2.0, 2.0, (count, n))
    third = rng.uniform(-50.0, 50.0, (count, n))
    samples = [(q[s], qd[s], third[s]) for s in range(count)]
    times: dict[str, list[float]] = {k: [] for k in calls}
    clock = time.perf_counter_ns
    gc.disable()
    try:
        for rep in range(reps + 1):  # the first pass warms
            for name, fn in calls.items():
                t0 = clock()
                for a, b, c in samples:
                    fn(a, b, c)
                if rep:
                    times[name].append((clock() - t0) / count / 1000.0)
    finally:
        gc.enable()
    res: dict = {"config": str(config), "n": n, "samples": count, "reps": reps, "us": {}}
    res["us"] = {k: round(float(np.median(v)), 3) for k, v in times.items()}
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", type=Path, default=ROOT / "configs" / "er3a.yaml")
    ap.add_argument("--reps", type=int, default=31)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    if a.reps < 1:
        ap.error(f"--reps: {a.reps} is not a positive count")
    res = measure(a.config, a.reps)
    if a.json:
        print(json.dumps(res, indent=2))
        return
    if "error" in res:
        print(f"bench_native: {res['error']}")
        return
    print(f"{res['config']}: {res['n']} axes, median µs per call from Python")
    for k, v in res["us"].items():
        print(f"  {k:62s} {v:7.3f}")


if __name__ == "__main__":
    main()
