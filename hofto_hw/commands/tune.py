"""``hofto-hw tune PARAMS FILES... -o thresholds.yaml``: choose observer gain and threshold
settings from contact-free recordings (free motion and static holds) with injected contacts.

Every observer named (``--observers``) runs over every file, and again with trains of
half-sine contact pulses subtracted from the measured torque (hofto_hw.replay.pulses). The
files are split into ``--folds`` groups; for each timing of the monitor (``--moving-times``:
how long the reversal term lasts after a stop; ``--standstill-times``: how long the standstill
term takes to rise after one) the thresholds are calibrated on all groups but one (sustained
residuals, every term) and judged on the left-out group; per joint the margin (``--margins``)
with 0 false alarms on every left-out group and the most pulses found wins, and the timing
whose joints find the most pulses wins (hofto_hw.replay.tuning). ``--rest-margins`` gives the
standstill term (the held friction at rest) its own margin per joint, searched with every margin
of the other terms.

Observer gains (hofto_hw.replay.gains; each checked by hofto_hw.observers.stability at the
recordings' rate, unstable ones reported and skipped): the momentum observer with each of
``--gains`` (its joints are decoupled, so each joint takes the gain that scores best on it);
HOFTO with its replay default and eq. (17) with its poles at each of ``--hofto-poles``
(``--hofto-substeps`` per sample). Every setting is judged the same way (0 false trips on
every left-out fold, most pulses found, then shortest median delay); the grid and the scores
go to the provenance. Each joint's margin is then raised by ``--cushion``, the standstill
margin by ``--rest-cushion`` (a margin just clean on the left-out runs is clean by luck as
often as not; measured: leaving 6 runs out at once, HOFTO joint 6 at its bare CV margin 0.1
tripped at 1.003x on one of them). With ``--fusion mean`` and both HOFTO and the momentum
observer tuned, the margins are chosen again with the mean of their ratios as the decision
(the monitor's ``logic: mean``, each row with its own envelope); the fused figures are
printed against each observer alone, and the decision with the best left-out score is named.
The winners are re-calibrated on all files and written with their provenance (files with
sha256, folds, settings, grids, the left-out sensitivity tables); the fused thresholds under
``fusion:``.
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
    parser.add_argument("--gains", default="10,20,40", help="momentum observer gains to try [1/s]")
    parser.add_argument(
        "--hofto-poles",
        default="20,40",
        help="HOFTO eq. (17) pole placements to try besides the replay default [rad/s] "
        "('' for none)",
    )
    parser.add_argument(
        "--hofto-substeps",
        type=positive_int,
        default=4,
        help="integration substeps per sample of the pole-placed HOFTO settings",
    )
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
        "--rest-margins",
        default="0,0.05,0.1,0.15,0.2,0.3,0.5,0.7,1,1.5,2",
        help="margins of the standstill term to try with every margin (per joint; '' = the "
        "standstill term takes the margin of the other terms)",
    )
    parser.add_argument(
        "--rest-cushion",
        type=finite_nonnegative_float,
        default=0.0,
        help="added to each joint's best clean standstill margin (measured: 0 keeps every rest "
        "cell of the thresholds before issue 11 and no false trip on 6 runs left out at once; "
        "0.05 lost a 10 N·m pulse at rest on HOFTO's joint 5, docs/sensitivity.md)",
    )
    parser.add_argument(
        "--fusion",
        choices=("mean", "none"),
        default="mean",
        help="also calibrate the margins on the mean of HOFTO's and the momentum observer's "
        "ratios (when both are tuned) and report it against each alone",
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


def _optional_floats(text: str, what: str) -> list[float]:
    """Like :func:`_floats`, '' (or only spaces) giving an empty list."""
    return [] if not text.strip() else _floats(text, what)


def _score(choice: Any) -> dict[str, float]:
    """A choice's cross-validated score for the provenance."""
    delay = -float(choice.score[1])  # inf when nothing was found
    return {
        "rate_sum": round(float(choice.score[0]), 4),
        "median_delay": round(delay, 4) if np.isfinite(delay) else None,
    }


def run(args: argparse.Namespace) -> int:
    from hofto_hw.commands.backend import observer_backend
    from hofto_hw.config.collision import CollisionConfig
    from hofto_hw.errors import UserError
    from hofto_hw.replay.defaults import OBSERVER_NAMES
    from hofto_hw.replay.gains import Variant, variants
    from hofto_hw.replay.session import load_for_replay, observer_for, recording_rate
    from hofto_hw.replay.setup import load_setup, observer_config, sha256_of
    from hofto_hw.replay.thresholds import (
        FusionThresholds,
        ObserverThresholds,
        ParametersRef,
        ThresholdsFile,
        write_thresholds,
    )
    from hofto_hw.replay.tuning import (
        choose,
        cross_validate,
        final_config,
        folds_of,
        per_joint_best,
        pulsed_runs,
    )

    gains = _floats(args.gains, "--gains")
    poles = _optional_floats(args.hofto_poles, "--hofto-poles")
    margins = _floats(args.margins, "--margins")
    rest_margins = _optional_floats(args.rest_margins, "--rest-margins") or None
    moving = _floats(args.moving_times, "--moving-times")
    still = _floats(args.standstill_times, "--standstill-times")
    amps = _floats(args.amplitudes, "--amplitudes")
    weights = _floats(args.rest_weights, "--rest-weights")
    if min(weights) <= 0:
        raise UserError(f"tune: --rest-weights must be > 0, got {args.rest_weights!r}")
    if min(moving) <= 0:
        raise UserError(f"tune: --moving-times must be > 0 s, got {args.moving_times!r}")
    if poles and min(poles) <= 0:
        raise UserError(f"tune: --hofto-poles must be > 0 rad/s, got {args.hofto_poles!r}")
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
    search = {
        "moving_times": moving,
        "standstill_times": still,
        "margins": margins,
        "folds": args.folds,
        "rest_weights": tuple(weights),
        "rest_margins": rest_margins,
        "feature_cache": {},  # the features depend on the recordings only: computed once
    }
    entries: dict[str, ObserverThresholds] = {}
    chosen: dict[str, Any] = {}
    tables: dict[str, list[str]] = {}
    kept: dict[str, Any] = {}  # name -> (choice, runs) of the chosen setting
    for name in names:
        tried, grid = variants(
            name,
            observer_config(name, setup),
            setup.model,
            rate,
            gains,
            poles,
            args.hofto_substeps,
            say,
        )
        if not tried:
            what = "--gains" if name == "momentum" else "setting"
            raise UserError(f"tune: no {name} {what} is stable at {rate:.4g} Hz")
        results = []
        for variant, record in zip(tried, [g for g in grid if g["stable"]], strict=True):
            obs_cfg = variant.config
            say(f"{name} {variant.label}: observer runs with pulses")
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
                say=lambda m, o=f"{name} {variant.label}": say(f"{o}: {m}"),
                **search,
            )
            try:
                choice = choose(cands, args.cushion, args.rest_cushion)
            except UserError as exc:
                say(f"{name} {variant.label}: {exc}")
                record["clean"] = False
                continue
            record.update(clean=True, **_score(choice))
            say(f"{name} {variant.label}: left-out score {record}")
            results.append((choice, variant, runs))
        if not results:
            raise UserError(
                f"tune: {name}: every setting gave false alarms on the left-out runs "
                "(try larger --margins)"
            )
        if name == "momentum" and len(results) > 1:
            # joint j's residual depends on joint j's gain only: the best gain per joint
            choice, runs, pick = per_joint_best([r[0] for r in results], [r[2] for r in results])
            labels = [results[i][1].label for i in pick]
            gain = [results[i][1].config.gain[j] for j, i in enumerate(pick)]  # type: ignore[union-attr]
            variant = Variant(
                "per joint: " + ", ".join(f"{g:g}" for g in gain),
                results[0][1].config.model_copy(update={"gain": gain}),
            )
            for record in grid:
                record["chosen_for_joints"] = [
                    j + 1 for j, lb in enumerate(labels) if lb == record["label"]
                ]
        else:
            choice, variant, runs = max(results, key=lambda r: r[0].score)
            for record in grid:
                record["chosen"] = record["label"] == variant.label
        obs_cfg = variant.config
        kept[name] = (choice, runs)
        monitor, peak = final_config(runs, template, choice)
        samples = sum(r.rec.n_samples for r in runs)
        entries[name] = ObserverThresholds(
            observer=obs_cfg, monitor=monitor, peak=[float(v) for v in peak], samples=samples
        )
        chosen[name] = {
            "observer": obs_cfg.model_dump(mode="json", exclude_none=True),
            "setting": variant.label,
            "grid": grid,
            "score": _score(choice),
            "moving_time": choice.moving_time,
            "standstill_time": choice.standstill_time,
            "margin": choice.margin,
            "rest_margin": choice.rest_margin,
            "rest_weight": choice.rest_weight,
            "sensitivity": _sensitivity(choice.stats, amps),
        }
        tables[name] = [
            f"{name} ({variant.label}): moving_time {choice.moving_time:g} s, standstill_time "
            f"{choice.standstill_time:g} s, margin per joint {choice.margin}, standstill margin "
            f"{choice.rest_margin}, rest weight {choice.rest_weight}",
            *_table(choice.stats, amps, args.width),
        ]
    fusion = None
    decision: dict[str, Any] | None = None
    rows = ("hofto", "momentum")
    if args.fusion == "mean" and all(r in kept for r in rows):
        say("fusion (mean of hofto's and momentum's ratios): cross-validation")
        pulsed = [kept[r][1] for r in rows]
        cands = cross_validate(pulsed, template, say=lambda m: say(f"fusion: {m}"), **search)
        try:
            fchoice = choose(cands, args.cushion, args.rest_cushion)
        except UserError as exc:
            say(f"fusion: {exc}")
            fchoice = None
        if fchoice is not None:
            monitors = {r: final_config(kept[r][1], template, fchoice)[0] for r in rows}
            fusion = FusionThresholds(logic="mean", monitors=monitors)
            chosen["fusion"] = {
                "logic": "mean",
                "rows": list(rows),
                "score": _score(fchoice),
                "moving_time": fchoice.moving_time,
                "standstill_time": fchoice.standstill_time,
                "margin": fchoice.margin,
                "rest_margin": fchoice.rest_margin,
                "rest_weight": fchoice.rest_weight,
                "sensitivity": _sensitivity(fchoice.stats, amps),
            }
            tables["fusion"] = [
                f"fusion (mean of {' and '.join(rows)}): moving_time {fchoice.moving_time:g} s, "
                f"margin per joint {fchoice.margin}, standstill margin {fchoice.rest_margin}",
                *_table(fchoice.stats, amps, args.width),
            ]
            kept["fusion"] = (fchoice, None)
    if len(kept) > 1:
        scores = {k: kept[k][0].score for k in kept}
        winner = max(scores, key=lambda k: scores[k])
        decision = {
            "decides": winner,
            "why": "most pulses found on the left-out runs with 0 false trips on every left-out "
            "fold (sum of detection rates over joints, sizes and states), then the shortest "
            "median delay",
            "scores": {k: _score(kept[k][0]) for k in kept},
        }
    fold = folds_of(len(args.files), args.folds)
    provenance = {
        "tool": "hofto-hw tune",
        "files": {f.name: sha256_of(f) for f in args.files},
        "folds": {f.name: k for f, k in zip(args.files, fold, strict=True)},
        "settings": {
            "observers": names,
            "gains": gains,
            "hofto_poles": poles,
            "hofto_substeps": args.hofto_substeps,
            "margins": margins,
            "rest_margins": rest_margins,
            "moving_times": moving,
            "standstill_times": still,
            "rest_weights": weights,
            "cushion": args.cushion,
            "rest_cushion": args.cushion if args.rest_cushion is None else args.rest_cushion,
            "fusion": args.fusion,
            "folds": args.folds,
            "debounce": args.debounce,
            "amplitudes": amps,
            "width": args.width,
            "pulses": args.pulses,
            "seed": args.seed,
        },
        "observers": chosen,
    }
    if decision is not None:
        provenance["decision"] = decision
    content = ThresholdsFile(
        robot=setup.config.robot.name,
        parameters=ParametersRef(file=args.params.name, sha256=sha256_of(args.params)),
        created=_dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        margin=max(max(c["margin"]) for c in chosen.values()),
        calibrated_on=[f.name for f in args.files],
        observers=entries,
        fusion=fusion,
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
    if decision is not None:
        figures = ", ".join(
            f"{k} {v['rate_sum']:.2f} / "
            + ("-" if v["median_delay"] is None else f"{v['median_delay']:.3f} s")
            for k, v in decision["scores"].items()
        )
        print(
            f"decision: {decision['decides']} (left-out score, sum of detection rates / median "
            f"delay: {figures}); every observer's own thresholds are written"
            + (", and the fused ones under fusion:" if fusion is not None else "")
        )
    print(f"wrote {args.output}")
    return 0
