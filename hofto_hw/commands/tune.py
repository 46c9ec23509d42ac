"""``hofto-hw tune PARAMS FILES... -o thresholds.yaml``: choose observer gain and threshold
settings from contact-free recordings (free motion and static holds) with injected contacts.

Every observer named (``--observers``) runs over every file, and again with trains of
half-sine contact pulses subtracted from the measured torque (hofto_hw.replay.pulses). The
files are split into ``--folds`` groups; for each timing of the monitor (``--moving-times``:
how long the reversal term lasts after a stop; ``--standstill-times``: how long the standstill
term takes to rise after one) the thresholds are calibrated on all groups but one (sustained
residuals, every term) and judged on the left-out group; per joint the margin (``--margins``)
with 0 false alarms on every left-out group and the most pulses found wins, and the timing
whose joints find the most pulses wins (hofto_hw.replay.tuning). For the momentum observer
each of ``--gains`` (checked by hofto_hw.observers.stability at the recordings' rate) is tried
the same way. Each joint's margin is then raised by ``--cushion`` (a margin just clean on the
left-out runs is clean by luck as often as not; measured: leaving 6 runs out at once, HOFTO
joint 6 at its bare CV margin 0.1 tripped at 1.003× on one of them). The winners are re-
calibrated on all files and written with their provenance (files with sha256, folds, settings,
the left-out sensitivity table).
"""

from __future__ import annotations

import argparse
import datetime as _dt
import sys
from pathlib import Path
from typing import Any

import numpy as np

from hofto_hw.commands.args import (
    finite_nonnegative_float,
    finite_positive_float,
    positive_int,
    refuse_overwrite,
    write_failed,
)

TUNED_BY_DEFAULT = ("momentum", "hofto", "dob", "eso", "direct")


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("params", type=Path, help="identified-parameters file")
    parser.add_argument(
        "files", nargs="+", type=Path, metavar="FILE", help="contact-free recordings"
    )
    parser.add_argument("-o", "--output", type=Path, required=True, help="thresholds file")
    parser.add_argument("--config", type=Path, help="robot config (default: <robot>.yaml)")
    parser.add_argument(
        "--observers",
        default=",".join(TUNED_BY_DEFAULT),
        help="observers to tune (comma-separated)",
    )
    parser.add_argument("--gains", default="20", help="momentum observer gains to try [1/s]")
    parser.add_argument(
        "--margins",
        default="0.1,0.2,0.3,0.4,0.5,0.6,0.7,0.8,0.9,1,1.3,1.6,2",
        help="calibration margins to try (per joint)",
    )
    parser.add_argument(
        "--moving-times", default="1,2", help="monitor moving_time values to try [s]"
    )
    parser.add_argument(
        "--standstill-times", default="0", help="monitor standstill_time values to try [s]"
    )
    parser.add_argument(
        "--cushion",
        type=finite_nonnegative_float,
        default=0.1,
        help="added to each joint's best clean margin (to the next margin tried)",
    )
    parser.add_argument(
        "--rest-weights",
        default="1",
        help="weights of the rest samples in the calibration objective to try (per joint)",
    )
    parser.add_argument(
        "--folds", type=positive_int, help="cross-validation folds (default: 8, at most 1 per file)"
    )
    parser.add_argument("--amplitudes", default="5,10,20", help="pulse sizes [N·m]")
    parser.add_argument(
        "--width", type=finite_positive_float, default=0.4, help="half-sine width [s]"
    )
    parser.add_argument(
        "--pulses", type=positive_int, default=2, help="pulse trains per file and size"
    )
    parser.add_argument(
        "--debounce", type=finite_nonnegative_float, default=0.03, help="debounce time [s]"
    )
    parser.add_argument("--seed", type=int, default=0)


def _floats(text: str, what: str) -> list[float]:
    from hofto_hw.errors import UserError

    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if not values or not all(np.isfinite(values)) or min(values) < 0:
        raise UserError(f"tune: {what}: expected comma-separated numbers >= 0, got {text!r}")
    return values


def _cell(rate: float, delay: float) -> str:
    if np.isnan(rate):
        return "      -    "
    return f"{rate:4.2f}/  -  " if np.isnan(delay) else f"{rate:4.2f}/{delay:5.3f}"


def _table(stats: Any, amps: list[float], width: float) -> list[str]:
    from hofto_hw.replay.pulses import STATES

    n = stats.hits.shape[2]
    rate, delay = stats.rate, stats.median_delay()
    lines = [
        f"  {'pulse':>9} {'state':6} " + " ".join(f"{'joint ' + str(j + 1):>11}" for j in range(n))
    ]
    for i, a in enumerate(amps):
        for s, st in enumerate(STATES):
            cells = " ".join(_cell(rate[i, s, j], delay[i, s, j]) for j in range(n))
            lines.append(f"  {a:5g} N·m {st:6} {cells}")
    return lines


def _sensitivity(stats: Any, amps: list[float]) -> dict[str, Any]:
    from hofto_hw.replay.pulses import STATES

    rate, delay = stats.rate, stats.median_delay()
    clean = lambda v: None if np.isnan(v) else float(v)  # noqa: E731
    return {
        st: {
            f"{a:g}": {
                "rate": [clean(v) for v in rate[i, s]],
                "median_delay": [clean(v) for v in delay[i, s]],
                "tries": stats.tries[i, s].astype(int).tolist(),
            }
            for i, a in enumerate(amps)
        }
        for s, st in enumerate(STATES)
    }


def run(args: argparse.Namespace) -> int:
    from hofto_hw.commands.backend import observer_backend
    from hofto_hw.config.collision import CollisionConfig
    from hofto_hw.errors import ConfigError, UserError
    from hofto_hw.observers.stability import check_observer
    from hofto_hw.replay.defaults import OBSERVER_NAMES
    from hofto_hw.replay.session import load_for_replay, observer_for, recording_rate
    from hofto_hw.replay.setup import load_setup, observer_config, sha256_of
    from hofto_hw.replay.thresholds import (
        ObserverThresholds,
        ParametersRef,
        ThresholdsFile,
        write_thresholds,
    )
    from hofto_hw.replay.tuning import choose, cross_validate, final_config, folds_of, pulsed_runs

    gains = _floats(args.gains, "--gains")
    margins = _floats(args.margins, "--margins")
    moving = _floats(args.moving_times, "--moving-times")
    still = _floats(args.standstill_times, "--standstill-times")
    amps = _floats(args.amplitudes, "--amplitudes")
    weights = _floats(args.rest_weights, "--rest-weights")
    if min(weights) <= 0:
        raise UserError(f"tune: --rest-weights must be > 0, got {args.rest_weights!r}")
    if min(moving) <= 0:
        raise UserError(f"tune: --moving-times must be > 0 s, got {args.moving_times!r}")
    names = [v.strip() for v in args.observers.split(",") if v.strip()]
    for name in names:
        if name not in OBSERVER_NAMES or name == "sta":
            raise UserError(
                f"tune: --observers: {name!r} cannot be tuned (choose from "
                f"{', '.join(o for o in OBSERVER_NAMES if o != 'sta')})"
            )
    if len(args.files) < 2:
        raise UserError("tune: give at least 2 contact-free recordings (some are left out)")
    if args.folds is None:
        args.folds = min(8, len(args.files))
    folds_of(len(args.files), args.folds)  # refuses a bad --folds before the long work
    refuse_overwrite(args.output, [args.params, args.config, *args.files], "--output")
    setup = load_setup(args.params, args.config)
    n = setup.model.n
    recs = [load_for_replay(setup, f, None) for f in args.files]
    rate = min(recording_rate(r) for r in recs)
    backend = observer_backend()
    say = lambda m: print(f"tune: {m}", file=sys.stderr, flush=True)  # noqa: E731
    template = CollisionConfig(base=[1.0] * n, debounce_time=args.debounce)
    entries: dict[str, ObserverThresholds] = {}
    chosen: dict[str, Any] = {}
    tables: dict[str, list[str]] = {}
    for name in names:
        base_obs = observer_config(name, setup)
        variants = []
        if name == "momentum":
            for gain in gains:
                cfg = base_obs.model_copy(update={"gain": [gain] * n})
                try:
                    check_observer(name, cfg, setup.model, rate)
                except ConfigError:
                    say(f"momentum gain {gain:g}: unstable at {rate:.4g} Hz, skipped")
                    continue
                variants.append(cfg)
            if not variants:
                raise UserError(
                    f"tune: no momentum gain in {args.gains!r} is stable at {rate:.4g} Hz"
                )
        else:
            variants.append(base_obs)
        best = None
        for obs_cfg in variants:
            say(f"{name}: observer runs with pulses ({obs_cfg.model_dump(exclude_none=True)})")
            runs = pulsed_runs(
                recs,
                lambda r, c=obs_cfg, o=name: observer_for(o, c, setup, r, backend),
                amps,
                args.width,
                args.pulses,
                args.seed,
            )
            cands = cross_validate(
                runs,
                template,
                moving,
                still,
                margins,
                args.folds,
                say=lambda m, o=name: say(f"{o}: {m}"),
                rest_weights=tuple(weights),
            )
            try:
                choice = choose(cands, args.cushion)
            except UserError as exc:
                say(f"{name}: {exc}")
                continue
            if best is None or choice.score > best[0].score:
                best = (choice, obs_cfg, runs)
        if best is None:
            raise UserError(
                f"tune: {name}: every setting gave false alarms on the left-out runs "
                "(try larger --margins)"
            )
        choice, obs_cfg, runs = best
        monitor, peak = final_config(runs, template, choice)
        samples = sum(r.rec.n_samples for r in runs)
        entries[name] = ObserverThresholds(
            observer=obs_cfg, monitor=monitor, peak=[float(v) for v in peak], samples=samples
        )
        chosen[name] = {
            "observer": obs_cfg.model_dump(mode="json", exclude_none=True),
            "moving_time": choice.moving_time,
            "standstill_time": choice.standstill_time,
            "margin": choice.margin,
            "rest_weight": choice.rest_weight,
            "sensitivity": _sensitivity(choice.stats, amps),
        }
        tables[name] = [
            f"{name}: moving_time {choice.moving_time:g} s, standstill_time "
            f"{choice.standstill_time:g} s, margin per joint {choice.margin}, rest weight "
            f"{choice.rest_weight}",
            *_table(choice.stats, amps, args.width),
        ]
        if name == "momentum":
            tables[name][0] += f", gain {obs_cfg.gain[0]:g}"
    fold = folds_of(len(args.files), args.folds)
    provenance = {
        "tool": "hofto-hw tune",
        "files": {f.name: sha256_of(f) for f in args.files},
        "folds": {f.name: k for f, k in zip(args.files, fold, strict=True)},
        "settings": {
            "observers": names,
            "gains": gains,
            "margins": margins,
            "moving_times": moving,
            "standstill_times": still,
            "rest_weights": weights,
            "cushion": args.cushion,
            "folds": args.folds,
            "debounce": args.debounce,
            "amplitudes": amps,
            "width": args.width,
            "pulses": args.pulses,
            "seed": args.seed,
        },
        "observers": chosen,
    }
    content = ThresholdsFile(
        robot=setup.config.robot.name,
        parameters=ParametersRef(file=args.params.name, sha256=sha256_of(args.params)),
        created=_dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        margin=max(max(c["margin"]) for c in chosen.values()),
        calibrated_on=[f.name for f in args.files],
        observers=entries,
        provenance=provenance,
    )
    try:
        write_thresholds(args.output, content)
    except OSError as exc:
        raise write_failed(args.output, "thresholds file", exc) from None
    print(
        f"sensitivity on the left-out runs (rate / median delay [s] after the pulse start), "
        f"{args.width:g} s half-sine pulses, {args.folds} folds:"
    )
    for lines in tables.values():
        print("\n".join(lines))
    print(f"wrote {args.output}")
    return 0
