"""The controller-side control tick for six axes against its pinocchio floor.

    python tools/bench_tick.py [--config configs/er3a.yaml] [--quick] [--json]

One tick: DriveGroup.read (TxPDO -> SI) -> DynamicsSnapshot.compute -> HOFTO (n = 2) and
momentum observer (update_snapshot) -> CollisionMonitor (safety/collision/, same backend) ->
command (CSP hold). The SimBus exchange (plant + emulated drives) runs before each tick but is
not part of it (on hardware the bus does that work); its cost is printed separately.

Figures (µs; median / p99 / p99.9):
- floor: the pinocchio calls the tick needs (ABA, CRBA, Coriolis matrix, gravity) back to back;
- the tick per part and in total, back to back and inside a 1 kHz and a 2 kHz loop that
  sleeps to absolute deadlines (libc clock_nanosleep, CLOCK_MONOTONIC, TIMER_ABSTIME;
  SCHED_FIFO 50 when permitted; gc frozen and off), for the numpy path and the compiled path;
- ratio of the tick's median to the floor;
- tracemalloc over 10,000 ticks after warm-up (growth) and the transient peak of each part;
- start-up: compiling the kernels cold (empty NUMBA_CACHE_DIR) and from the cache;
- the collision monitor's compiled kernel checked against its numpy reference on the same
  inputs, timed side by side (tools/bench_monitor.py times the loop's two-level monitor).
The machine is shared and noisy: compare medians and ratios, not single runs.
"""

from __future__ import annotations

import argparse
import ctypes
import ctypes.util
import gc
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

PARTS = ("read", "snapshot", "hofto", "momentum", "monitor", "command")
CLOCK_MONOTONIC = 1
TIMER_ABSTIME = 1


class _Timespec(ctypes.Structure):
    _fields_ = [("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long)]


class AbsSleep:
    """Sleep until an absolute CLOCK_MONOTONIC deadline [ns] (libc clock_nanosleep)."""

    def __init__(self) -> None:
        libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
        self._fn = libc.clock_nanosleep
        self._fn.argtypes = [
            ctypes.c_int,
            ctypes.c_int,
            ctypes.POINTER(_Timespec),
            ctypes.c_void_p,
        ]
        self._ts = _Timespec()
        self._ref = ctypes.byref(self._ts)

    def until(self, deadline_ns: int) -> None:
        self._ts.tv_sec, self._ts.tv_nsec = divmod(deadline_ns, 1_000_000_000)
        while self._fn(CLOCK_MONOTONIC, TIMER_ABSTIME, self._ref, None) == 4:  # EINTR
            pass


def realtime() -> str:
    """SCHED_FIFO 50 if permitted; returns the policy in use."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(50))
        return "SCHED_FIFO 50"
    except (PermissionError, OSError, AttributeError):
        return "SCHED_OTHER (SCHED_FIFO not permitted)"


def stats(us: np.ndarray) -> dict[str, float]:
    return {
        "median": float(np.median(us)),
        "p99": float(np.percentile(us, 99)),
        "p999": float(np.percentile(us, 99.9)),
        "max": float(us.max()),
    }


def make_collision_config(n: int):
    from hofto_hw.config.collision import CollisionConfig

    return CollisionConfig(
        base=[20.0] * n,
        velocity_gain=[5.0] * n,
        acceleration_gain=[1.0] * n,
        reversal_margin=[4.0] * n,
        debounce_time=0.002,
    )


class Rig:
    """SimBus + DriveGroup + snapshot + HOFTO + momentum + monitor for one backend."""

    def __init__(self, cfg, backend: str) -> None:
        from drivers.cia402.drive_group import DriveGroup
        from drivers.cia402.state_machine import Mode
        from drivers.sim.simbus import make_sim_bus
        from hofto_hw.model import RobotModel
        from hofto_hw.model.snapshot import DynamicsSnapshot
        from hofto_hw.observers import make_observer
        from hofto_hw.observers.registry import replay_default
        from safety.collision import CollisionMonitor

        self.dt = cfg.cycle_time
        self.bus = make_sim_bus(cfg, external=False)
        self.bus.open()
        g = self.group = DriveGroup.from_config(self.bus, cfg.bus)
        g.configure(cfg.bus.drives)
        g.set_mode(Mode.CSP)
        g.enable()
        model = self.model = RobotModel.from_config(cfg.robot)
        n = model.n
        hcfg = cfg.observers.get("hofto") or replay_default("hofto", n)
        mcfg = cfg.observers.get("momentum") or replay_default("momentum", n)
        self.hofto = make_observer(hcfg, model, backend=backend)
        self.momentum = make_observer(mcfg, model, backend=backend)
        self.backend = self.hofto.backend
        self.snap = DynamicsSnapshot(model, self.hofto.needs | self.momentum.needs, self.backend)
        self.monitor = CollisionMonitor(make_collision_config(n), backend=self.backend)
        self.hofto.reset(g.q, g.qd)
        self.momentum.reset(g.q, g.qd)
        self.monitor.reset(g.qd)
        # a slow sine around the start pose keeps the arm moving (CSP targets)
        self.q0 = g.q.copy()
        self.target = g.q.copy()
        self.amp = np.array([0.3, 0.2, 0.2, 0.4, 0.4, 0.5])
        self.k = 0
        self.times = np.zeros(len(PARTS) + 1, dtype=np.int64)

    def exchange(self) -> None:
        self.k += 1
        s = math.sin(2.0 * math.pi * 0.5 * self.k * self.dt)
        np.multiply(self.amp, s, out=self.target)
        np.add(self.target, self.q0, out=self.target)
        self.bus.exchange()

    def tick(self) -> None:
        """One controller-side tick; stamps self.times (ns) at each part's end."""
        clock, t = time.perf_counter_ns, self.times
        g, snap, dt = self.group, self.snap, self.dt
        t[0] = clock()
        g.read()
        t[1] = clock()
        snap.compute(g.q, g.qd, g.tau)
        t[2] = clock()
        est = self.hofto.update_snapshot(snap, dt)
        t[3] = clock()
        self.momentum.update_snapshot(snap, dt)
        t[4] = clock()
        self.monitor.update(est, g.qd, dt)
        t[5] = clock()
        g.command_position(self.target)
        t[6] = clock()


def floor_us(rig: Rig, ticks: int, cold: bool = False) -> np.ndarray:
    """The pinocchio calls of the tick, back to back, on the rig's own samples (``cold``:
    each after a SimBus exchange, whose plant evicts the caches as it does in the tick)."""
    import pinocchio as pin

    pm, pd = rig.model.pin_model, rig.model.pin_model.createData()
    rows = []
    for _ in range(200):
        rig.exchange()
        rig.group.read()
        rows.append((rig.group.q.copy(), rig.group.qd.copy(), rig.group.tau.copy()))
    out = np.empty(ticks)
    clock = time.perf_counter_ns
    gc.disable()
    for k in range(ticks):
        q, qd, tau = rows[k % len(rows)]
        if cold:
            rig.exchange()
        t0 = clock()
        pin.aba(pm, pd, q, qd, tau)
        pin.crba(pm, pd, q)
        pin.computeCoriolisMatrix(pm, pd, q, qd)
        pin.computeGeneralizedGravity(pm, pd, q)
        out[k] = clock() - t0
    gc.enable()
    return out / 1000.0


def run_ticks(rig: Rig, ticks: int, period_ns: int | None) -> dict:
    """``ticks`` ticks back to back (period None) or one per period at absolute deadlines."""
    parts = np.zeros((ticks, len(PARTS)))
    total = np.zeros(ticks)
    exch = np.zeros(ticks)
    wake = np.zeros(ticks)
    sleeper = AbsSleep()
    clock = time.perf_counter_ns
    mono = time.monotonic_ns
    for _ in range(500):  # warm-up
        rig.exchange()
        rig.tick()
    gc.collect()
    gc.freeze()
    gc.disable()
    overruns = 0
    try:
        deadline = mono() + (period_ns or 0)
        for k in range(ticks):
            if period_ns is not None:
                sleeper.until(deadline)
                wake[k] = (mono() - deadline) / 1000.0
                deadline += period_ns
            t0 = clock()
            rig.exchange()
            exch[k] = clock() - t0
            rig.tick()
            t = rig.times
            parts[k] = np.diff(t)
            total[k] = t[-1] - t[0]
            if period_ns is not None and mono() > deadline:
                overruns += 1
                deadline = mono() + period_ns  # skip missed periods
    finally:
        gc.enable()
        gc.unfreeze()
    parts /= 1000.0
    total /= 1000.0
    exch /= 1000.0
    res = {
        "tick": stats(total),
        "parts": {name: stats(parts[:, i]) for i, name in enumerate(PARTS)},
        "exchange": stats(exch),
    }
    res["hofto_plus_momentum"] = stats(parts[:, 2] + parts[:, 3])
    res["median"], res["p99"], res["p999"] = (
        res["tick"]["median"],
        res["tick"]["p99"],
        res["tick"]["p999"],
    )
    if period_ns is not None:
        res["wakeup"] = stats(wake)
        res["overruns"] = overruns
        res["period_us"] = period_ns / 1000.0
    return res


def allocations(rig: Rig, ticks: int) -> dict:
    """tracemalloc: growth over ``ticks`` ticks after warm-up (a bus exchange every 100th
    tick), transient peak per part."""
    for _ in range(500):
        rig.exchange()
        rig.tick()
    tracemalloc.start(10)
    try:
        for _ in range(200):
            rig.exchange()
            rig.tick()
        before = tracemalloc.take_snapshot()
        cur0, _ = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        for k in range(ticks):
            if k == ticks // 2:
                cur_mid, _ = tracemalloc.get_traced_memory()
            if k % 100 == 0:  # the simulated plant is slow under tracemalloc; the tick is
                rig.exchange()  # the same work on repeated TxPDO data
            rig.tick()
        after = tracemalloc.take_snapshot()
        cur1, _ = tracemalloc.get_traced_memory()
        diffs = [
            d
            for d in after.compare_to(before, "lineno")
            if d.size_diff > 0 and "tracemalloc" not in str(d.traceback)
        ]
        growth = [f"{d.traceback[0]}: +{d.size_diff} B ({d.count_diff:+d} blocks)" for d in diffs]
        # transient peak per part: each part alone, peak above the level before it
        g, snap, dt = rig.group, rig.snap, rig.dt
        est = rig.hofto.update_snapshot(snap, dt)
        calls = {
            "read": g.read,
            "snapshot": lambda: snap.compute(g.q, g.qd, g.tau),
            "hofto": lambda: rig.hofto.update_snapshot(snap, dt),
            "momentum": lambda: rig.momentum.update_snapshot(snap, dt),
            "monitor": lambda: rig.monitor.update(est, g.qd, dt),
            "command": lambda: g.command_position(rig.target),
        }
        transient = {}
        for name, fn in calls.items():
            fn()
            base, _ = tracemalloc.get_traced_memory()
            tracemalloc.reset_peak()
            fn()
            _, peak = tracemalloc.get_traced_memory()
            transient[name] = peak - base
    finally:
        tracemalloc.stop()
    return {
        "ticks": ticks,
        "growth_bytes": cur1 - cur0,
        "growth_second_half_bytes": cur1 - cur_mid,
        "growth_sites": growth[:10],
        "transient_peak_bytes": transient,
    }


_STARTUP = """
import time, sys
t0 = time.perf_counter()
from hofto_hw.observers import kernels
from hofto_hw.config import load_config
from hofto_hw.model import RobotModel
from hofto_hw.observers import make_observer
from hofto_hw.observers.registry import OBSERVER_TYPES, replay_default
t1 = time.perf_counter()
model = RobotModel.from_config(load_config(sys.argv[1]).robot)
t2 = time.perf_counter()
for name in OBSERVER_TYPES:
    make_observer(replay_default(name, model.n), model, backend="numba" if name != "direct"
                  else "numpy")
t3 = time.perf_counter()
print(t1 - t0, t3 - t2)
"""


def startup(config: Path) -> dict:
    """Seconds to import and to compile/warm all observer kernels, cold and cached."""
    from hofto_hw.observers import kernels

    if not kernels.available():
        return {"available": False, "reason": kernels.unavailable_reason()}
    out = {"available": True}
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache, PYTHONPATH=str(ROOT))
        for label in ("cold", "cached"):
            r = subprocess.run(
                [sys.executable, "-c", _STARTUP, str(config)],
                env=env,
                capture_output=True,
                text=True,
                check=True,
            )
            imp, comp = (float(x) for x in r.stdout.split())
            out[label] = {"import_s": imp, "build_and_warm_s": comp}
    return out


def monitor_prototype(rig: Rig, ticks: int) -> dict:
    """The monitor's compiled kernel (safety/collision/kernel.py) against its numpy reference
    on the rig's samples, timed side by side (keys kept from the prototype's time)."""
    from hofto_hw.observers import kernels
    from safety.collision import CollisionMonitor

    if not kernels.available():
        return {"available": False}
    cfg = make_collision_config(rig.model.n)
    ref = CollisionMonitor(cfg, backend="numpy")
    new = CollisionMonitor(cfg, backend="numba")
    n = rig.model.n
    rng = np.random.default_rng(0)
    samples = []
    for k in range(ticks):
        rig.exchange()
        rig.group.read()
        tau = 25.0 * np.sin(0.01 * k + np.arange(n)) + rng.normal(0, 2.0, n)
        samples.append((tau, rig.group.qd.copy()))
    worst = 0.0
    mismatch = 0
    for tau, qd in samples:
        d_ref = ref.update(tau, qd, rig.dt)
        d_new = new.update(tau, qd, rig.dt)
        worst = max(worst, float(np.abs(new.threshold - ref.threshold).max()))
        mismatch += int(d_new != d_ref or not np.array_equal(new.joints, ref.joints))
    clock = time.perf_counter_ns
    t_ref = np.zeros(ticks)
    t_new = np.zeros(ticks)
    gc.disable()
    for k, (tau, qd) in enumerate(samples):
        t0 = clock()
        ref.update(tau, qd, rig.dt)
        t1 = clock()
        new.update(tau, qd, rig.dt)
        t2 = clock()
        t_ref[k], t_new[k] = t1 - t0, t2 - t1
    gc.enable()
    return {
        "available": True,
        "numpy_monitor": stats(t_ref / 1000.0),
        "compiled_prototype": stats(t_new / 1000.0),
        "threshold_max_abs_diff": worst,
        "decision_mismatches": mismatch,
        "ticks": ticks,
    }


def bench(cfg_path: Path, quick: bool) -> dict:
    from hofto_hw.config import load_config
    from hofto_hw.model.snapshot import pinocchio_traits
    from hofto_hw.observers import kernels

    cfg = load_config(cfg_path)
    cfg2k = cfg.model_copy(update={"loop": cfg.loop.model_copy(update={"rate_hz": 2000.0})})
    n_b2b = 2000 if quick else 20000
    n_1k = 2000 if quick else 20000
    n_2k = 2000 if quick else 40000
    policy = realtime()
    rig = Rig(cfg, "numpy")
    floor = floor_us(rig, n_b2b)
    res: dict = {
        "machine": platform.platform(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "pinocchio": pinocchio_traits(rig.model).__dict__,
        "numba": kernels.available() and kernels._numba.__version__,
        "scheduler": policy,
        "quick": quick,
        "floor_us": float(np.median(floor)),
        "floor": stats(floor),
        "floor_after_exchange": stats(floor_us(rig, 1000 if quick else 10000, cold=True)),
        "paths": {},
    }
    for backend in ("numpy", "numba"):
        if backend == "numba" and not kernels.available():
            res["paths"]["numba"] = {"skipped": kernels.unavailable_reason()}
            continue
        r = Rig(cfg, backend)
        r2 = Rig(cfg2k, backend)
        path = {
            "back_to_back": run_ticks(r, n_b2b, None),
            "loop_1khz": run_ticks(r, n_1k, 1_000_000),
            "loop_2khz": run_ticks(r2, n_2k, 500_000),
        }
        for key in ("back_to_back", "loop_1khz", "loop_2khz"):
            path[key]["ratio_to_floor"] = path[key]["median"] / res["floor_us"]
        path["loop_2khz"]["share_of_period"] = path["loop_2khz"]["median"] / 500.0
        if not quick or backend == "numba" or not kernels.available():
            path["alloc"] = allocations(r, 2_000 if quick else 10_000)
        res["paths"][backend] = path
    best = "numba" if "back_to_back" in res["paths"].get("numba", {}) else "numpy"
    res["path"] = best
    for key in ("back_to_back", "loop_1khz", "loop_2khz"):
        res[key] = res["paths"][best][key]
    res["startup"] = {"skipped": "--quick"} if quick else startup(cfg_path)
    res["monitor_prototype"] = monitor_prototype(rig, 1000 if quick else 10000)
    return res


def targets(res: dict) -> list[tuple[str, str, bool]]:
    f = res["floor_us"]
    l1, l2, b = res["loop_1khz"], res["loop_2khz"], res["back_to_back"]
    hm = res["back_to_back"]["hofto_plus_momentum"]["median"]
    return [
        (
            "1 kHz loop median <= 3x floor",
            f"{l1['median']:.1f} <= {3 * f:.1f}",
            l1["median"] <= 3 * f,
        ),
        ("1 kHz loop p99 <= 100 µs", f"{l1['p99']:.1f}", l1["p99"] <= 100),
        (
            "back to back median <= 2x floor",
            f"{b['median']:.1f} <= {2 * f:.1f}",
            b["median"] <= 2 * f,
        ),
        ("HOFTO n=2 + momentum median <= 15 µs", f"{hm:.1f}", hm <= 15),
        (
            "2 kHz tick median <= 25 % of 500 µs",
            f"{l2['median']:.1f} ({100 * l2['share_of_period']:.1f} %)",
            l2["share_of_period"] <= 0.25,
        ),
    ]


def print_report(res: dict) -> None:
    print(
        f"{res['machine']}, python {res['python']}, numpy {res['numpy']}, "
        f"pinocchio {res['pinocchio']['version']}, numba {res['numba']}; {res['scheduler']}"
    )
    tr = res["pinocchio"]
    print(
        f"pinocchio: stable Data views {tr['stable_views']}, full symmetric M "
        f"{tr['full_mass_matrix']}"
    )
    fl = res["floor"]
    fc = res["floor_after_exchange"]
    print(
        f"floor (aba+crba+coriolis+gravity): median {fl['median']:.1f}  p99 {fl['p99']:.1f} µs"
        f"; each after a SimBus exchange (cold caches): median {fc['median']:.1f} µs"
    )
    for backend, path in res["paths"].items():
        if "skipped" in path:
            print(f"\n[{backend}] skipped: {path['skipped']}")
            continue
        print(f"\n[{backend} path]   µs: median / p99 / p99.9")
        head = f"{'':12s}" + "".join(f"{p:>22s}" for p in (*PARTS, "tick", "exchange"))
        print(head)
        for key in ("back_to_back", "loop_1khz", "loop_2khz"):
            r = path[key]
            cells = [r["parts"][p] for p in PARTS] + [r["tick"], r["exchange"]]
            row = "".join(f"{c['median']:7.1f}/{c['p99']:6.1f}/{c['p999']:6.1f} " for c in cells)
            print(f"{key:12s}{row}")
            extra = f"  ratio tick/floor {r['ratio_to_floor']:.2f}"
            extra += f", HOFTO+momentum median {r['hofto_plus_momentum']['median']:.1f}"
            if "wakeup" in r:
                w = r["wakeup"]
                extra += (
                    f", wake-up {w['median']:.0f}/{w['p99']:.0f}/{w['p999']:.0f}, "
                    f"overruns {r['overruns']}"
                )
            print(extra)
        a = path.get("alloc")
        if a is None:
            continue
        print(
            f"  tracemalloc over {a['ticks']} ticks (exchange included): growth "
            f"{a['growth_bytes']} B, in the second half {a['growth_second_half_bytes']} B; "
            f"transient peak per part [B]: {a['transient_peak_bytes']}"
        )
        for site in a["growth_sites"]:
            print(f"    {site}")
    s = res["startup"]
    if s.get("available"):
        print(
            f"\nstart-up: import {s['cold']['import_s']:.2f} s; build + compile all kernels "
            f"cold {s['cold']['build_and_warm_s']:.2f} s, cached "
            f"{s['cached']['build_and_warm_s']:.2f} s"
        )
    m = res["monitor_prototype"]
    if m.get("available"):
        print(
            f"monitor: numpy {m['numpy_monitor']['median']:.1f} µs median, compiled "
            f"prototype {m['compiled_prototype']['median']:.1f} µs (threshold diff "
            f"{m['threshold_max_abs_diff']:.1e}, decision mismatches "
            f"{m['decision_mismatches']})"
        )
    print(f"\ntargets ({res['path']} path):")
    for name, value, ok in targets(res):
        print(f"  {'met ' if ok else 'MISS'}  {name}: {value}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", type=Path, default=ROOT / "configs" / "er3a.yaml")
    parser.add_argument(
        "--quick",
        action="store_true",
        help="a short run (< 30 s): fewer ticks, tracemalloc over 2,000 ticks on the compiled "
        "path only, "
        "no start-up (compilation) measurement",
    )
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    res = bench(args.config, args.quick)
    res["targets"] = [{"target": n, "value": v, "met": ok} for n, v, ok in targets(res)]
    if args.json:
        print(json.dumps(res, indent=2))
    else:
        print_report(res)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
