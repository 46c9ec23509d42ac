"""Collision detection delay vs. free-motion margin of the loop's observers, by gain sweep.

The observers never act on the arm, so the estimates the loop would compute for any observer
setting can be reproduced from one recording of what the loop measured (q, qd, tau, dt and
the reference acceleration the collision phase logic reads). This tool records, on the
simulated arm of a config (``run.model_error``, noise, the payload; ``--clock sim``):

- the scripted collision (``run.collision``) with the collision monitor disarmed, so the
  estimate's whole rise is recorded;
- ``--free`` seconds of the fast free-motion demo path with no contact;

then, for each candidate setting (a ``name=value`` list of overrides of ``loop.observers`` /
``safety.collision``), reruns HOFTO and the momentum observer and the loop's collision monitor
(safety.collision.CollisionLevels) over both recordings and prints per setting the
detection delay after contact onset per observer, and the largest free-motion estimate /
collision threshold per joint (a stop happens at 1.0). Every candidate's gains pass the loop
rate's stability check (hofto_hw.observers.stability) first; an unstable one is reported.

    python tools/sweep_detection.py --config configs/er3a.yaml --free 60 \
        --set "hofto.L=20000" --set "hofto.L=50000;momentum.gain=300" [--json]

Overrides (';'-separated inside one --set): ``hofto.L=<Lipschitz constant>`` (Levant's
recursive-differentiator gains for order 2 scaled to L), ``momentum.gain=<1/s>``,
``collision.nominal=<a,b,...>``, ``collision.acceleration=<...>``, ``debounce=<s>``,
``velocity_gain=<...>``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from hofto_hw.config.loader import load_config  # noqa: E402
from hofto_hw.config.models import SystemConfig  # noqa: E402
from hofto_hw.errors import ConfigError  # noqa: E402

#: the paper's lambdas (Levant's recursive differentiator), stage 1 first, per HOFTO order
LAMBDAS = {1: (2.0, 1.5, 1.1), 2: (5.0, 3.0, 1.5, 1.1), 3: (8.0, 5.0, 3.0, 1.5, 1.1)}


def levant_gains(
    lipschitz: float, n: int = 6, order: int = 2, lam: tuple[float, ...] | None = None
) -> list[list[float]]:
    """HOFTO recursive-form gains ((order + 2) stages x n joints): stage i of k = order + 2
    gets lambda_i·L^(1/(k - i + 1)), L the Lipschitz constant of x3's (order-1)-th derivative
    [rad/s^(order+2)]."""
    lam = LAMBDAS[order] if lam is None else lam
    k = order + 2
    return [[round(lam[i] * lipschitz ** (1.0 / (k - i)), 4)] * n for i in range(k)]


def binomial_gains(w0: float, n: int = 6, order: int = 2) -> list[list[float]]:
    """eq. (17)-form gains whose linearisation (powers 1) has all order + 2 poles at -w0
    [rad/s]: L_i = C(k, i)·w0^i, k = order + 2."""
    from math import comb

    k = order + 2
    return [[round(comb(k, i) * w0**i, 6)] * n for i in range(1, k + 1)]


def levant_powers(order: int) -> list[float]:
    """Stage powers (k - i)/(k - i + 1)... of the recursive differentiator: (k-1)/k, ..., 0."""
    k = order + 2
    return [(k - 1 - i) / (k - i) for i in range(k)]


@dataclass
class Recording:
    q: np.ndarray  # (T, n)
    qd: np.ndarray
    tau: np.ndarray
    qdd_ref: np.ndarray
    dt: np.ndarray  # (T,)
    tick: np.ndarray  # (T,) loop tick numbers
    q0: np.ndarray
    qd0: np.ndarray
    onset_tick: int = -1  # first tick whose exchange includes the contact (-1: none)


def disarmed(cfg: SystemConfig) -> SystemConfig:
    """``cfg`` with collision thresholds no estimate reaches (the rise is recorded whole)."""
    col = cfg.safety.collision
    big = [1e9] * len(col.collision.nominal)
    sets = {
        k: col.contact.model_copy(update={"nominal": big, "acceleration": big})
        for k in ("contact", "collision")
    }
    safety = cfg.safety.model_copy(update={"collision": col.model_copy(update=sets)})
    return cfg.model_copy(update={"safety": safety})


def record(cfg: SystemConfig, seconds: float, contact: bool) -> Recording:
    """Run the loop on the simulated arm (sim clock) for ``seconds`` and keep its inputs."""
    from hofto_hw.control.joint_motion import MOVE
    from hofto_hw.recording.record import MemorySink, tick_dtype
    from hofto_hw.runtime.compose import build, loop_observer_names

    run = cfg.model_copy(update={"run": cfg.run.model_copy(update={"drag": None})})
    ticks = int(round(seconds * cfg.loop.rate_hz))
    k = len(loop_observer_names(cfg))
    sink = MemorySink(tick_dtype(6, k), capacity=ticks + 8)
    system = build(disarmed(run), clock="sim", sink=sink, contact=contact)
    g = system.group
    q0, qd0 = g.q.copy(), g.qd.copy()
    system.tick.mode_request = MOVE
    system.loop.run(max_ticks=ticks)
    if system.tick.stop.latched:
        raise RuntimeError(f"recording stopped: {system.tick.stop.latched_names()}")
    recs = sink.last_ticks()
    t = recs["t"]
    dt = np.diff(np.concatenate([[0.0], t]))
    dt[0] = 1.0 / cfg.loop.rate_hz
    onset = system.contact.onset_tick if system.contact is not None else -1
    system.close()
    return Recording(
        recs["q"].copy(),
        recs["qd"].copy(),
        recs["tau"].copy(),
        recs["qdd_cmd"].copy(),
        dt,
        recs["tick"].copy(),
        q0,
        qd0,
        onset,
    )


def apply_overrides(cfg: SystemConfig, spec: str) -> SystemConfig:
    """``cfg`` with the ``name=value;...`` overrides of the module docstring applied."""
    obs = dict(cfg.loop.observers or {})
    col = cfg.safety.collision
    col_upd: dict = {}
    n = len(col.collision.nominal)
    hofto: dict = {}
    for item in filter(None, (s.strip() for s in spec.split(";"))):
        name, _, value = item.partition("=")
        vals = [float(v) for v in value.split(",")]
        vec = vals * n if len(vals) == 1 else vals
        if name in (
            "hofto.L",
            "hofto.order",
            "hofto.lam",
            "hofto.substeps",
            "hofto.w0",
            "hofto.sigma",
        ):
            hofto[name[6:]] = vals
        elif name == "momentum.gain":
            obs["momentum"] = obs["momentum"].model_copy(update={"gain": vec})
        elif name in (
            "collision.nominal",
            "collision.acceleration",
            "contact.nominal",
            "contact.acceleration",
        ):
            level, phase = name.split(".")
            base = col_upd.get(level, getattr(col, level))
            col_upd[level] = base.model_copy(update={phase: vec})
        elif name == "debounce":
            col_upd["debounce_time"] = vals[0]
        elif name == "velocity_gain":
            col_upd["velocity_gain"] = vec
        else:
            raise SystemExit(f"sweep_detection: unknown override {name!r}")
    if hofto:
        order = int(hofto.get("order", [obs["hofto"].order])[0])
        lam = tuple(hofto["lam"]) if "lam" in hofto else None
        if "w0" in hofto:  # eq. (17) form, all poles of the linearisation at -w0
            sigma = hofto.get("sigma", [-0.05])[0]
            upd = {
                "order": order,
                "form": "eq17",
                "powers": None,
                "sigma": sigma,
                "gains": binomial_gains(hofto["w0"][0], n, order),
            }
        else:
            upd = {
                "order": order,
                "powers": levant_powers(order),
                "sigma": None,
                "gains": levant_gains(hofto.get("L", [20000.0])[0], n, order, lam),
            }
        if "substeps" in hofto:
            upd["substeps"] = int(hofto["substeps"][0])
        obs["hofto"] = type(obs["hofto"]).model_validate({**obs["hofto"].model_dump(), **upd})
    loop = cfg.loop.model_copy(update={"observers": obs})
    safety = cfg.safety.model_copy(update={"collision": col.model_copy(update=col_upd)})
    return cfg.model_copy(update={"loop": loop, "safety": safety})


def estimates(cfg: SystemConfig, rec: Recording) -> tuple[list[str], np.ndarray]:
    """The loop observers' estimates over ``rec``: names, array (T, k, n) [N·m]."""
    from hofto_hw.commands.backend import observer_backend
    from hofto_hw.observers import make_observer
    from hofto_hw.observers.stability import check_observer
    from hofto_hw.runtime.compose import build_model, loop_observer_names, loop_observer_table

    model = build_model(cfg)
    table = loop_observer_table(cfg)
    names = loop_observer_names(cfg)
    backend = observer_backend()
    out = np.zeros((rec.q.shape[0], len(names), model.n))
    for r, name in enumerate(names):
        check_observer(name, table[name], model, cfg.loop.rate_hz)
        obs = make_observer(table[name], model, backend=backend)
        obs.reset(rec.q0, rec.qd0)
        for i in range(rec.q.shape[0]):
            out[i, r] = obs.update(rec.q[i], rec.qd[i], rec.tau[i], float(rec.dt[i]))
    return names, out


def monitor(cfg: SystemConfig, names: list[str], est: np.ndarray, rec: Recording) -> dict:
    """Run CollisionLevels over the estimates: first collision tick per row (each row judged
    on its own) and the largest estimate/threshold ratio per row and joint."""
    from hofto_hw.runtime.compose import build_model
    from safety.collision import CollisionLevels
    from safety.stop import StopController

    out: dict = {"first_tick": {}, "max_ratio": {}}
    # a trip needs the ratio above 1 for debounce_time: the peak that counts is the largest
    # ratio held over that many consecutive ticks
    hold = max(1, int(round(cfg.safety.collision.debounce_time * cfg.loop.rate_hz)))
    for r, name in enumerate(names):
        col_cfg = cfg.safety.collision.model_copy(update={"observer": name})
        levels = CollisionLevels(col_cfg, names, build_model(cfg))
        stop = StopController.from_config(cfg.safety.categories)
        peak = np.zeros(levels.n)
        window = np.full((hold, levels.n), np.inf)
        held = np.zeros(levels.n)
        first = -1
        for i in range(est.shape[0]):
            stop.begin_tick(int(rec.tick[i]))
            levels.update(stop, est[i], rec.q[i], rec.qd[i], rec.qdd_ref[i], float(rec.dt[i]))
            window[i % hold] = levels.ratio[r]
            window.min(axis=0, out=held)
            np.maximum(peak, held, out=peak)
            if levels.first_tick[r] >= 0 and first < 0:
                first = int(levels.first_tick[r])
                if rec.onset_tick >= 0:
                    break
        out["first_tick"][name] = first
        out["max_ratio"][name] = peak.tolist()
    return out


def evaluate(cfg: SystemConfig, hit: Recording, free: Recording | None) -> dict:
    """Delays [ms] per observer on ``hit``; free-motion max ratios per observer and joint."""
    names, est = estimates(cfg, hit)
    res = monitor(cfg, names, est, hit)
    period_ms = 1000.0 / cfg.loop.rate_hz
    delays = {}
    for name, first in res["first_tick"].items():
        # as the run summary: the detecting tick's time minus the contact's start
        delays[name] = None if first < 0 else round((first - hit.onset_tick + 1) * period_ms, 3)
    out = {"delay_ms": delays}
    if free is not None:
        names, est = estimates(cfg, free)
        out["free_max_ratio"] = monitor(cfg, names, est, free)["max_ratio"]
        out["free_max_abs"] = {
            name: np.abs(est[:, r]).max(axis=0).round(3).tolist() for r, name in enumerate(names)
        }
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", type=Path, default=ROOT / "configs" / "er3a.yaml")
    ap.add_argument("--free", type=float, default=30.0, help="free-motion seconds recorded")
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        dest="sets",
        help="overrides for one candidate (repeat for more candidates)",
    )
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--cache", type=Path, help="folder keeping the recordings between runs")
    args = ap.parse_args(argv)
    cfg = load_config(args.config)
    t0 = time.perf_counter()
    c = cfg.run.collision
    hit = _cached(args.cache, "hit", lambda: record(cfg, c.start + c.rise_time + 0.1, True))
    free = None
    if args.free > 0:
        free = _cached(args.cache, f"free{args.free:g}", lambda: record(cfg, args.free, False))
    say = lambda m: print(m, file=sys.stderr, flush=True)  # noqa: E731
    say(f"recorded in {time.perf_counter() - t0:.1f} s")
    results = []
    for spec in args.sets or [""]:
        try:
            res = evaluate(apply_overrides(cfg, spec), hit, free)
        except ConfigError as e:
            res = {"error": str(e)}
        res["setting"] = spec or "(config)"
        results.append(res)
        if not args.json:
            _print(res)
    if args.json:
        print(json.dumps({"free_seconds": args.free, "results": results}, indent=1))
    return 0


def _cached(folder: Path | None, name: str, make):
    """The recording ``name`` from ``folder`` (made and saved there when absent)."""
    import pickle

    if folder is None:
        return make()
    path = folder / f"{name}.pkl"
    if path.exists():
        with path.open("rb") as f:
            return pickle.load(f)
    rec = make()
    folder.mkdir(parents=True, exist_ok=True)
    with path.open("wb") as f:
        pickle.dump(rec, f)
    return rec


def _print(res: dict) -> None:
    print(f"== {res['setting']}")
    if "error" in res:
        print(f"   {res['error']}")
        return
    d = res["delay_ms"]
    print("   delay ms: " + ", ".join(f"{k} {v}" for k, v in d.items()))
    for name, ratios in res.get("free_max_ratio", {}).items():
        print(
            f"   free {name:8s} max |est|/thr: "
            + " ".join(f"{r:.2f}" for r in ratios)
            + "   max |est|: "
            + " ".join(f"{a:.2f}" for a in res["free_max_abs"][name])
        )
    sys.stdout.flush()


if __name__ == "__main__":
    raise SystemExit(main())
