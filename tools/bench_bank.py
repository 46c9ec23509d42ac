"""Where the observer bank's time goes: the tick's one compiled observer call
(hofto_hw.observers.bank.ObserverBank.update) for the main job's observers, per observer and
per operation, six axes.

    python tools/bench_bank.py [--config configs/er3a.yaml] [--blocks 8] [--json]

Samples (q, qd, tau) are those of ``hofto-hw run``'s tick (400 ticks of the main job on the
simulated bus); before each timed call the tick's dynamics snapshot is computed for the next
sample (untimed, as in the tick, where it runs just before the bank). Variants are
interleaved in ``--blocks`` blocks of ``--per-block`` calls so that the machine's load hits
all alike; each variant's observers are fresh and reset at the start of each block.
Figures: median and p99 µs of one call. Variants:

- ``call``: the bank kernel with a table of no observers (the Python→compiled call itself);
- ``momentum``, ``hofto``: a bank of that observer alone; ``bank``: the tick's bank (every
  observer the main job runs, as ``compose`` builds it);
- ``hofto, powers 1`` / ``hofto, powers 0``: the same HOFTO (order, form, gains, substeps)
  with every stage power 1 (linear injection: no power, no sign) / 0 (sign only), so
  ``hofto - hofto, powers 1`` is what the fractional powers cost and ``hofto, powers 1 -
  call`` the loops, the chain's prediction and M·z3.

``powers_per_call`` counts the fractional powers sig^p(x), 0 < p < 1, one call evaluates.
Timing goals live here, never in tests.
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
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))


def _samples(cfg, ticks: int = 400):
    """(system, [(q, qd, tau)]) of the main job's tick, moving along run.path."""
    from hofto_hw.control.joint_motion import MOVE
    from hofto_hw.runtime.compose import build

    system = build(cfg, clock="sim", contact=False)
    system.tick.overrun_limit = 1 << 40
    system.tick.mode_request = MOVE
    rows = []

    def keep() -> bool:
        g = system.group
        rows.append((g.q.copy(), g.qd.copy(), g.tau.copy()))
        return False

    system.loop.run(max_ticks=ticks, should_stop=keep)
    return system, rows[100:]


def measure(config: Path, blocks: int, per_block: int) -> dict:
    from hofto_hw.config import load_config
    from hofto_hw.observers import HoftoObserver, make_observer
    from hofto_hw.observers import kernels as K
    from hofto_hw.observers.bank import ObserverBank
    from hofto_hw.runtime.compose import loop_observer_table

    cfg = load_config(config)
    system, samples = _samples(cfg)
    try:
        tick = system.tick
        snap = tick.snapshot
        model = system.model
        dt = 1.0 / cfg.loop.rate_hz
        table = loop_observer_table(cfg)
        names = [o.name for o in tick.observers]
        hofto_cfg = table["hofto"]

        def fresh(name: str):
            return make_observer(table[name], model, backend="numba")

        def hofto_with(power: float):
            base = fresh("hofto").core
            return HoftoObserver(
                model,
                base.gains,
                np.full(base.stages, power),
                base.form,
                base.substeps,
                base.discretisation,
                backend="numba",
            )

        out = np.zeros((len(names), model.n))
        variants: dict[str, tuple[list, object]] = {}

        def bank_of(make):
            def build_bank():
                obs = make()
                return obs, ObserverBank(obs, snap, out[: len(obs)])

            return build_bank

        variants["bank"] = bank_of(lambda: [fresh(n) for n in names])
        variants["hofto"] = bank_of(lambda: [fresh("hofto")])
        variants["momentum"] = bank_of(lambda: [fresh("momentum")])
        variants["hofto, powers 1"] = bank_of(lambda: [hofto_with(1.0)])
        variants["hofto, powers 0"] = bank_of(lambda: [hofto_with(0.0)])
        built = {k: make() for k, make in variants.items()}
        for key, (_, bank) in built.items():
            if len(bank.fused) != len(bank.observers):
                raise SystemExit(f"{key}: not every observer fused ({bank.rest} run alone)")
        scratch = np.zeros((1, snap.n))

        def call_empty() -> None:
            K.bank_update(
                (None,) * 5,
                built["momentum"][1].terms,
                scratch,
                snap.q,
                snap.qd,
                snap.tau,
                snap.finite,
                dt,
            )

        timings: dict[str, list[float]] = {k: [] for k in ["call", *built]}
        clock = time.perf_counter_ns
        gc.disable()
        try:
            for _ in range(blocks):
                for key in timings:
                    if key == "call":
                        fn = call_empty
                    else:
                        obs, bank = built[key]
                        q0, qd0, _ = samples[0]
                        for o in obs:
                            o.reset(q0, qd0)
                        fn = bank.update
                    acc = timings[key]
                    for k in range(per_block):
                        q, qd, tau = samples[k % len(samples)]
                        snap.compute(q, qd, tau)
                        if key == "call":
                            t0 = clock()
                            fn()
                            t1 = clock()
                        else:
                            t0 = clock()
                            fn(dt)
                            t1 = clock()
                        acc.append((t1 - t0) / 1000.0)
        finally:
            gc.enable()
        res = {
            k: {"median_us": float(np.median(v)), "p99_us": float(np.percentile(v, 99))}
            for k, v in timings.items()
        }
        med = {k: v["median_us"] for k, v in res.items()}
        core = built["hofto"][0][0].core
        fractional = int(np.sum((core.powers > 0.0) & (core.powers < 1.0)))
        derived = {
            "fractional powers (hofto - hofto, powers 1)": med["hofto"] - med["hofto, powers 1"],
            "sign only vs linear (hofto, powers 0 - hofto, powers 1)": med["hofto, powers 0"]
            - med["hofto, powers 1"],
            "hofto loops, prediction, M·z3 (hofto, powers 1 - call)": med["hofto, powers 1"]
            - med["call"],
            "momentum arithmetic (momentum - call)": med["momentum"] - med["call"],
        }
        return {
            "meta": {
                "config": str(config),
                "observers": names,
                "hofto": {
                    "order": hofto_cfg.order,
                    "form": core.form,
                    "substeps": core.substeps,
                    "discretisation": core.discretisation,
                    "powers": [float(p) for p in core.powers],
                },
                "powers_per_call": fractional * core.substeps * model.n,
                "blocks": blocks,
                "per_block": per_block,
                "python": platform.python_version(),
                "machine": platform.machine(),
            },
            "results": res,
            "derived_us": derived,
        }
    finally:
        system.close()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", type=Path, default=ROOT / "configs" / "er3a.yaml")
    parser.add_argument("--blocks", type=int, default=8)
    parser.add_argument("--per-block", type=int, default=2000)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    from hofto_hw import jit

    if not jit.available():
        print(f"bench_bank: the compiled path is unavailable: {jit.unavailable_reason()}")
        return 2
    r = measure(args.config, args.blocks, args.per_block)
    if args.json:
        print(json.dumps(r, indent=2))
        return 0
    m = r["meta"]
    print(
        f"observer bank, {m['observers']}, six axes; HOFTO {m['hofto']}; "
        f"{m['powers_per_call']} fractional powers per call"
    )
    print(f"{'':64}{'median µs':>10}{'p99 µs':>10}")
    for name, v in r["results"].items():
        print(f"{name:<64}{v['median_us']:10.2f}{v['p99_us']:10.2f}")
    for name, v in r["derived_us"].items():
        print(f"{name:<64}{v:10.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
