"""Benchmark the CiA-402 drive layer and the in-process SimBus (per-cycle cost).

Prints medians over repeated blocks (the machine is shared: read ratios, not absolutes):
- master side: DriveGroup.read() + command_position() (the tick's drive-layer cost), and
  read() alone with its kernel run as Python (backend python) and compiled (numba);
- emulator: EmulatedDrives.step() without the plant (drive logic only);
- plant.step() alone, and a whole SimBus.exchange() (drives + plant + copies).

Usage: .venv/bin/python tools/bench_cia402.py [--config configs/er3a.yaml] [--json]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from drivers.cia402.drive_group import DriveGroup
from drivers.cia402.state_machine import Mode
from hofto_hw.config.loader import load_config
from hofto_hw.runtime.build import build_sim_bus

ROOT = Path(__file__).resolve().parents[1]


def _median_us(fn: Callable[[], None], n: int, blocks: int) -> float:
    per = []
    for _ in range(blocks):
        t0 = time.perf_counter()
        for _ in range(n):
            fn()
        per.append((time.perf_counter() - t0) / n * 1e6)
    return statistics.median(per)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=str(ROOT / "configs" / "er3a.yaml"))
    ap.add_argument("--cycles", type=int, default=500, help="cycles per block")
    ap.add_argument("--blocks", type=int, default=7)
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    args = ap.parse_args()

    cfg = load_config(args.config)
    bus = build_sim_bus(cfg, external=False)
    group = DriveGroup.from_config(bus, cfg.bus)
    bus.open()
    group.configure(cfg.bus.drives)
    group.set_mode(Mode.CSP)
    group.enable()
    q = group.q.copy()

    def master() -> None:
        group.read()
        group.command_position(q)

    drives, plant = bus.drives, bus.plant
    rx = bus.rx.copy()
    real_step = plant.step

    def drives_only() -> None:
        drives.step(rx)

    res = {"config": Path(args.config).name, "axes": group.n}
    res["master_read_command_us"] = _median_us(master, args.cycles, args.blocks)
    for backend in ("python", "numba"):
        g = DriveGroup.from_config(bus, cfg.bus, backend=backend)  # type: ignore[arg-type]
        res[f"read_{g.backend}_us"] = _median_us(g.read, args.cycles, args.blocks)
    res["simbus_exchange_us"] = _median_us(bus.exchange, args.cycles, args.blocks)
    res["plant_step_us"] = _median_us(
        lambda: real_step(plant.tau_applied), args.cycles, args.blocks
    )
    plant.step = lambda tau: None  # type: ignore[method-assign]
    try:
        res["emulated_drives_step_us"] = _median_us(drives_only, args.cycles, args.blocks)
    finally:
        del plant.step
    res["drive_share_of_exchange"] = res["emulated_drives_step_us"] / res["simbus_exchange_us"]
    assert np.all(group.states == 4), "drives left operation enabled during the benchmark"
    if args.json:
        print(json.dumps(res))
    else:
        for k, v in res.items():
            print(f"{k:28s} {v:.3f}" if isinstance(v, float) else f"{k:28s} {v}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
