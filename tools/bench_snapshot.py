"""Per-call cost of the tick's pinocchio side: the dynamics snapshot (DynamicsSnapshot.compute
and each call it makes), the feed-forward inverse dynamics (ModelData.inverse_dynamics) and
the bare pinocchio algorithms, on the System ``hofto-hw run`` builds (six axes).

    python tools/bench_snapshot.py [--config configs/er3a.yaml] [--blocks 6] [--json]

Each call is timed alone (back to back, warm caches) and "flushed": with the simulated bus's
exchange (the plant and the emulated drives, ~300 µs of Python) run just before it, as in
the tick, where it evicts the caches between two calls. Samples (q, qd, tau) are those of the
running tick; the variants are interleaved in blocks so that the machine's load hits all
alike. Figures: median µs. ``floor`` = ABA + CRBA + Coriolis matrix + gravity back to back
(tools/bench_tick.py's floor). The tick's snapshot and feed-forward are timed beside the
other compiled variant: native (pinocchio's C++ inside one compiled call,
hofto_hw.model.native) and pinocchio's Python calls plus one kernel. Timing goals live here,
never in tests.
"""

from __future__ import annotations

import argparse
import gc
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tools"))


def measure(config: Path, blocks: int, per_block: int = 300) -> dict:
    import pinocchio as pin
    from bench_tick import build_system

    from hofto_hw.config import load_config
    from hofto_hw.model.data import ModelData
    from hofto_hw.model.native import unavailable_reason
    from hofto_hw.model.snapshot import DynamicsSnapshot

    system = build_system(load_config(config), 1000.0, "sim")
    rows = []

    def keep() -> bool:
        g = system.group
        rows.append((g.q.copy(), g.qd.copy(), g.tau.copy()))
        return False

    try:
        system.loop.run(max_ticks=400, should_stop=keep)
        rows = rows[100:]
        tick = system.tick
        snap, ff = tick.snapshot, tick.feedforward
        model = system.model
        pm = model.pin_model
        pd = pm.createData()
        out = np.zeros(model.n)
        # the other compiled variant beside the tick's: with the native library (one call) and
        # without (pinocchio's Python calls and one kernel)
        native = not snap.native
        snap2 = DynamicsSnapshot(model, snap.needs, snap.backend, native=native)
        ff2 = ModelData(model, ff.backend, native=native)
        label = {True: "native, one call", False: "pinocchio Python + kernel"}

        def floor(q, qd, tau) -> None:
            pin.aba(pm, pd, q, qd, tau)
            pin.crba(pm, pd, q)
            pin.computeCoriolisMatrix(pm, pd, q, qd)
            pin.computeGeneralizedGravity(pm, pd, q)

        calls = {
            f"snapshot.compute ({label[snap.native]})": lambda q, qd, tau: snap.compute(q, qd, tau),
            **{f"snapshot part: {k}": f for k, f in snap.parts().items()},
            f"snapshot.compute ({label[snap2.native]})": lambda q, qd, tau: snap2.compute(
                q, qd, tau
            ),
            **{f"snapshot part: {k}": f for k, f in snap2.parts().items()},
            "floor (aba+crba+coriolis+gravity)": floor,
            f"feedforward ({label[ff.native]})": lambda q, qd, tau: ff.inverse_dynamics(
                q, qd, tau, out=out
            ),
            f"feedforward ({label[ff2.native]})": lambda q, qd, tau: ff2.inverse_dynamics(
                q, qd, tau, out=out
            ),
            "pin.rnea": lambda q, qd, tau: pin.rnea(pm, pd, q, qd, tau),
            "pin.nonLinearEffects": lambda q, qd, tau: pin.nonLinearEffects(pm, pd, q, qd),
            "pin.computeAllTerms": lambda q, qd, tau: pin.computeAllTerms(pm, pd, q, qd),
            "pin.computeMinverse": lambda q, qd, tau: pin.computeMinverse(pm, pd, q),
            "empty Python call": lambda q, qd, tau: None,
        }
        exchange = system.bus.exchange
        clock = time.perf_counter_ns
        times: dict[tuple[str, bool], list[int]] = {(k, f): [] for k in calls for f in (0, 1)}
        gc.disable()
        try:
            for b in range(blocks):
                for flush in (False, True):
                    for name, fn in calls.items():
                        t = times[(name, flush)]
                        for i in range(per_block):
                            q, qd, tau = rows[(i + 7 * b) % len(rows)]
                            if flush:
                                exchange()
                            t0 = clock()
                            fn(q, qd, tau)
                            t.append(clock() - t0)
        finally:
            gc.enable()
        res = {
            name: {
                "alone": float(np.median(times[(name, False)])) / 1000.0,
                "flushed": float(np.median(times[(name, True)])) / 1000.0,
            }
            for name in calls
        }
        return {
            "snapshot_backend": snap.backend,
            "snapshot_native": snap.native,
            "feedforward_backend": getattr(ff, "backend", "python"),
            "feedforward_native": ff.native,
            "native_unavailable": unavailable_reason(),
            "native_build": _build_info(),
            "needs": snap.needs.name,
            "calls_per_variant": blocks * per_block,
            "median_us": res,
        }
    finally:
        system.close()


def _build_info() -> str:
    """The native library in use: its file and the pinocchio it was built against."""
    from hofto_hw.model import native

    lib = native.library_path()
    if lib is None or not native.ready():
        return native.unavailable_reason() or "no native library in this install"
    return f"{lib.name} (built against pinocchio {native.built_against()})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", type=Path, default=ROOT / "configs" / "er3a.yaml")
    ap.add_argument("--blocks", type=int, default=6, help="interleaved blocks of 300 calls")
    ap.add_argument("--json", action="store_true", help="print JSON only")
    args = ap.parse_args()
    res = measure(args.config, args.blocks)
    if args.json:
        print(json.dumps(res, indent=2))
        return
    print(
        f"snapshot {res['snapshot_backend']} ({res['needs']}, native {res['snapshot_native']}), "
        f"feed-forward {res['feedforward_backend']} (native {res['feedforward_native']}); "
        f"median µs of {res['calls_per_variant']}"
    )
    if res["native_unavailable"]:
        print(f"native dynamics unavailable: {res['native_unavailable']}")
    print(f"native library: {res['native_build']}")
    print(f"{'call':58s} {'alone':>7s} {'flushed':>8s}")
    for name, r in res["median_us"].items():
        print(f"{name:58s} {r['alone']:7.2f} {r['flushed']:8.2f}")


if __name__ == "__main__":
    main()
